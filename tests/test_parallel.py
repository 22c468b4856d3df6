"""An unreachable Dask scheduler is one line naming its address, at once (issue 34 item 9)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from shspec.cli import main
from shspec.errors import SchedulerError, ShspecError
from shspec.mesh import icosphere, save_mesh
from shspec.core.parallel import make_executor


@pytest.fixture
def closed_port() -> str:
    with socket.socket() as s:  # a port that was just free: nothing listens there now
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"tcp://127.0.0.1:{port}"


def test_a_closed_port_fails_at_once_with_its_address(closed_port):
    pytest.importorskip("distributed")
    start = time.perf_counter()
    with pytest.raises(SchedulerError, match=closed_port.replace(".", r"\.")) as info:
        make_executor(scheduler=closed_port, connect_timeout=5)
    assert time.perf_counter() - start < 3  # distributed alone retried for its 30 s timeout
    assert isinstance(info.value, ShspecError)
    with pytest.raises(SchedulerError, match="not a Dask scheduler address"):
        make_executor(scheduler="tcp://[bad")


@pytest.fixture
def silent_server():
    """A local TCP server that accepts connections and never speaks; it ends with the test."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(4)
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"


def test_a_server_that_never_answers_fails_in_bounded_time(silent_server):
    """Issue 50, item 11: distributed waits for the server's handshake without limit, so this hung for good."""
    pytest.importorskip("distributed")
    with pytest.raises(SchedulerError, match=f"the server at {silent_server} accepts connections but does not "
                                             "answer as a Dask scheduler within 1 s"):
        make_executor(scheduler=silent_server, connect_timeout=1)


@pytest.mark.parametrize("address, words", [
    ("127.0.0.1:99999", "'127.0.0.1:99999' names the port 99999, which cannot exist (ports are 1 to 65535)"),
    ("tcp://127.0.0.1:0", "names the port 0, which cannot exist"),
    ("nonsense://", "'nonsense://' has the unknown scheme 'nonsense': Dask schedulers listen at tcp://host:port"),
    ("tcp://:8786", "names no host"),
])
def test_an_address_that_cannot_be_one_is_named_before_connecting(address, words):
    """Issue 50, item 19: an invalid port was reported as "Connection refused", an unknown scheme as a server that
    does not answer."""
    pytest.importorskip("distributed")
    with pytest.raises(SchedulerError) as info:
        make_executor(scheduler=address, connect_timeout=1)
    assert words in str(info.value)


def test_the_cli_prints_one_line(tmp_path, capsys, closed_port):
    pytest.importorskip("distributed")
    mesh = tmp_path / "ico.obj"
    save_mesh(icosphere(1), mesh)
    code = main(["mesh-spectrum", str(mesh), str(mesh), "--out", str(tmp_path / "out"), "--scheduler", closed_port])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert err.strip().count("\n") == 0 and closed_port in err


def test_a_scheduler_without_dask_installed_says_which_extra_to_install(monkeypatch, capsys, tmp_path):
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # as if shspec[dask] were not installed
    with pytest.raises(SchedulerError, match=r'pip install "shspec\[dask\]"'):
        make_executor(scheduler="tcp://127.0.0.1:8786")
    assert main(["fit", "--target", "blob", "--lmax", "8", "--lmax-factor", "6", "--numeig", "20", "--starts", "1",
                 "--scheduler", "tcp://127.0.0.1:8786", "--out", str(tmp_path / "fit")]) == 1
    err = capsys.readouterr().err
    assert "shspec[dask]" in err and "Traceback" not in err


def test_leaving_a_worker_pool_by_an_exception_does_not_wait_for_its_jobs():
    # the workers ignore Ctrl-C (their owner decides), so the pool must not wait for a job nobody wants any more
    start = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        with make_executor(workers=2) as pool:
            jobs = [pool.submit(time.sleep, 120) for _ in range(3)]
            while not all(job.running() for job in jobs[:2]):
                time.sleep(0.1)
            time.sleep(1.0)
            raise KeyboardInterrupt
    assert time.perf_counter() - start < 60
    assert all(job.done() for job in jobs)  # cancelled, or failed with their workers


_KILLED_OWNER = """
import os, signal, time
from shspec.core.parallel import _pool_processes, make_executor
pool = make_executor(workers=2)
jobs = [pool.submit(time.sleep, 300) for _ in range(2)]
while not all(job.running() for job in jobs):
    time.sleep(0.1)
time.sleep(1.0)
print(" ".join(str(process.pid) for process in _pool_processes(pool)), flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has ended (gone, or a zombie its new parent has not reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads process states from /proc")
def test_the_workers_of_a_killed_owner_end_themselves():
    # an owner killed without stopping its pool (SIGKILL, a batch system's SIGTERM) left its workers running their
    # jobs, a fit's start for many minutes, on the machine's cores
    run = subprocess.run([sys.executable, "-c", _KILLED_OWNER], capture_output=True, text=True, timeout=120)
    pids = [int(p) for p in run.stdout.split()]
    assert run.returncode == -signal.SIGKILL and len(pids) == 2, run.stderr
    deadline = time.monotonic() + 30
    while not all(_ended(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert all(_ended(pid) for pid in pids)


def _compile_here() -> int:
    import numba

    return numba.njit(lambda x: x + 1)(1)  # compiling re-reads numba's configuration from the environment


@pytest.mark.slow
def test_a_worker_compiles_numba_code():
    # with a cold numba cache a pool's worker compiles shspec's kernels at their first call; the worker's one-thread
    # setup once changed NUMBA_NUM_THREADS under numba's running threads, and every compilation raised
    with make_executor(workers=2) as pool:  # workers=1 runs here
        assert pool.submit(_compile_here).result(timeout=120) == 2
