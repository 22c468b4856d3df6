"""Ctrl-C during an atomic write always stops it and removes the temporary file (issue 34 item 6)."""

from __future__ import annotations

import signal
import tempfile
import weakref

import pytest

from shspec.core import atomic
from shspec.cli import main
from shspec.gaunt import build_table, save_table


def _sigint_in_a_weakref_callback():
    # Python runs the SIGINT handler at the next bytecode, here inside the callback; a KeyboardInterrupt raised
    # there is printed as "Exception ignored" and dropped, as when h5py's object registry collected an object
    class Thing:
        pass

    thing = Thing()
    ref = weakref.ref(thing, lambda _: [signal.raise_signal(signal.SIGINT), sum(range(100))])
    del thing
    return ref


@pytest.fixture
def sigint_when_the_temporary_file_appears(monkeypatch):
    real = tempfile.mkstemp

    def mkstemp(*args, **kwargs):
        out = real(*args, **kwargs)
        _sigint_in_a_weakref_callback()
        return out

    monkeypatch.setattr(atomic.tempfile, "mkstemp", mkstemp)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_swallowed_by_a_callback_still_stops_the_write(tmp_path, sigint_when_the_temporary_file_appears):
    table = build_table(4, 2)
    with pytest.raises(KeyboardInterrupt):
        save_table(table, tmp_path)
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob("*.h5"))
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def test_ctrl_c_while_precompute_writes_exits_130(tmp_path, capsys, sigint_when_the_temporary_file_appears):
    assert main(["precompute", "--lmax", "4", "--lmax-factor", "2", "--quiet", "--cache-dir", str(tmp_path)]) == 130
    assert "interrupted" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob("*.h5"))


def test_a_write_without_interruption_is_unchanged(tmp_path):
    with atomic.atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("x")
    assert (tmp_path / "a.txt").read_text() == "x" and not list(tmp_path.glob("*.tmp"))
