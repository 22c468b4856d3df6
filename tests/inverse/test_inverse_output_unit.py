"""A fit's outputs are one unit (issue 50 item 6): when one file cannot be written the folder keeps every file of
the previous fit, and a fit that writes fewer files removes the previous fit's others, so that a folder never
mixes two fits."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import matplotlib.figure
import pytest

from shspec.core import atomic
from shspec.errors import NotPositiveError, OutputError
from shspec.galerkin import HarmonicModel
from shspec.inverse import FitOptions, fit, plots
from shspec.fitting.targets import blob_factor, harmonic_target
from shspec.inverse.output import write_result


@pytest.fixture(scope="module")
def tiny_result():
    target = harmonic_target(blob_factor(), lmax=8, numeig=10)
    return fit(target, HarmonicModel(8, 4), FitOptions(starts=1, max_iter=2, basin_hops=0, schedule=(),
                                                       progress=False))


def _files(folder: Path) -> dict:
    """Every file under ``folder`` (hidden ones and subfolders included) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _too_large_for(name):
    real = matplotlib.figure.Figure.savefig

    def savefig(self, fname, **kwargs):
        if Path(fname).name.startswith(name):
            Path(fname).write_bytes(b"\x89PNG partial")
            raise OSError(errno.EFBIG, "File too large")
        return real(self, fname, **kwargs)

    return savefig


@pytest.mark.slow
def test_a_figure_that_cannot_be_written_leaves_every_file_of_the_previous_fit(tmp_path, tiny_result,
                                                                                monkeypatch):
    write_result(tiny_result, tmp_path)
    (tmp_path / "checkpoint.h5").write_bytes(b"not the fit's output")
    before = _files(tmp_path)
    assert {"result.h5", "summary.json", "history.png", "factors.png"} <= set(before)
    # factors.png is the last figure written: result.h5, summary.json and the other figures of the new fit were
    # in the folder before it failed, beside the old factors.png
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", _too_large_for("factors.png"))
    with pytest.raises(OutputError, match=r"cannot write .*factors\.png: the file would exceed .*ulimit -f.*"
                                          r"those of .* are as they were"):
        write_result(tiny_result, tmp_path)
    assert _files(tmp_path) == before  # nothing half-written or temporary either


def test_a_fit_that_writes_fewer_files_removes_the_previous_fits_others(tmp_path, tiny_result, monkeypatch):
    write_result(tiny_result, tmp_path)
    (tmp_path / "notes.txt").write_text("the user's")

    def no_alignment(result):
        raise NotPositiveError("the aligned expansion dips below 0")

    monkeypatch.setattr(plots, "plot_factors", no_alignment)
    write_result(tiny_result, tmp_path)
    assert not (tmp_path / "factors.png").exists()  # the previous fit's, beside this one's other figures
    assert (tmp_path / "history.png").exists() and (tmp_path / "notes.txt").read_text() == "the user's"
    write_result(tiny_result, tmp_path, figures=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [atomic.MANIFEST, "notes.txt", "result.h5", "summary.json"]


def test_a_folder_written_before_the_list_of_outputs_loses_its_old_figures(tmp_path, tiny_result):
    (tmp_path / "factors.png").write_bytes(b"an older shspec's figure")
    write_result(tiny_result, tmp_path, figures=False)
    assert not (tmp_path / "factors.png").exists()


def test_a_swap_cut_short_marks_the_folder_incomplete(tmp_path, tiny_result, monkeypatch):
    write_result(tiny_result, tmp_path, figures=False)
    real, calls = os.replace, []

    def replace(src, dst):  # the marker goes in, then the new result.h5; the new summary.json does not
        if Path(dst).parent == tmp_path:
            calls.append(Path(dst).name)
            if len(calls) == 3:
                raise OSError(errno.EIO, "Input/output error")
        real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(OutputError, match="mixes two runs.*INCOMPLETE"):
        write_result(tiny_result, tmp_path, figures=False)
    assert calls == [atomic.INCOMPLETE, "result.h5", "summary.json"]
    assert "two runs" in (tmp_path / atomic.INCOMPLETE).read_text()
    monkeypatch.setattr(atomic.os, "replace", real)
    write_result(tiny_result, tmp_path, figures=False)  # a complete write takes the mark away
    assert not (tmp_path / atomic.INCOMPLETE).exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(atomic.TEMP_SUFFIX)]
