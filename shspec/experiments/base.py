"""The experiment runner: one folder per run with the config, raw results, figures and a report.

An experiment is a function ``run(config, out, progress) -> Finding`` registered with :func:`register`.  The runner
merges its defaults (or its ``--quick`` preset) with a user's TOML file, writes ``config.json``, calls it, and writes
``report.md`` (the finding in one paragraph with its numbers, tables, figures) and ``meta.json`` (versions, wall and
CPU time, and the machine's load average before and after, without which a time on a shared machine cannot be
judged).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import time
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from .._version import __version__
from ..errors import InvalidArgumentError
from ..core.atomic import atomic_outputs
from ..core.outputs import ensure_directory, write_csv
from ..report import experiment_markdown
from ..core.resources import load_average

__all__ = ["Experiment", "Finding", "EXPERIMENTS", "register", "run_experiment", "load_config"]


@dataclass
class Finding:
    """What an experiment found.

    Attributes
    ----------
    summary : str
        One paragraph stating the finding with its numbers.
    tables : dict[str, list[dict]]
        Named tables (rows of equal keys), written to CSV and shown in the report.
    figures : list[str]
        PNG file names inside the run folder, in report order.
    numbers : dict
        The key numbers, machine-readable (also in ``meta.json``).
    """

    summary: str
    tables: dict = field(default_factory=dict)
    figures: list = field(default_factory=list)
    numbers: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Experiment:
    """A registered experiment: its name, what it reproduces, default and quick configurations, and run function."""

    name: str
    title: str
    reproduces: str
    defaults: dict
    quick: dict
    expected_minutes: float
    run: Callable


EXPERIMENTS: dict[str, Experiment] = {}


def register(experiment: Experiment) -> Experiment:
    EXPERIMENTS[experiment.name] = experiment
    return experiment


def load_config(path) -> dict:
    """Read a TOML configuration file into a dict."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except OSError as exc:
        raise InvalidArgumentError(f"cannot read the config file {path}: {exc.strerror}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise InvalidArgumentError(f"{path} is not valid TOML: {exc}") from exc


def _merge(base: dict, override: dict, name: str) -> dict:
    unknown = sorted(set(override) - set(base))
    if unknown:
        raise InvalidArgumentError(f"unknown keys for experiment {name!r}: {unknown}; known: {sorted(base)}")
    out = dict(base)
    for key, value in override.items():
        if type(value) is not type(base[key]) and not (isinstance(base[key], float) and isinstance(value, int)):
            raise InvalidArgumentError(f"{name}.{key} must be {type(base[key]).__name__}, got {value!r}")
        out[key] = value
    return out


#: Environment variables that set the threads of BLAS and numba, recorded with every run.
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def run_experiment(name: str, out, *, config_path=None, quick: bool = False, progress: bool = True) -> Path:
    """Run experiment ``name`` into the folder ``out``; returns the path of its ``report.md``.

    The run's files are one unit (:func:`shspec.core.atomic.atomic_outputs`): they are written into a staging folder
    and replace those of an earlier run in ``out`` only when all of them are written, so that an error, Ctrl-C or a
    full disk leaves ``out`` as it was, never a folder whose files come from two runs.

    Raises
    ------
    InvalidArgumentError
        If there is no experiment ``name``, or the config file cannot be read or does not fit it.
    OutputError
        If ``out`` cannot be written (it is then as it was).
    """
    if name not in EXPERIMENTS:
        raise InvalidArgumentError(f"no experiment {name!r}; available: {', '.join(sorted(EXPERIMENTS))}")
    exp = EXPERIMENTS[name]
    config = dict(exp.quick if quick else exp.defaults)
    if config_path is not None:
        config = _merge(config, load_config(config_path), name)
    out = ensure_directory(out)
    with atomic_outputs(out) as files:
        _run(exp, config, files.folder, quick=quick, config_path=config_path, progress=progress)
    report = out / "report.md"
    if progress:
        print(f"{name}: report {report}")
    return report


def _run(exp: Experiment, config: dict, folder: Path, *, quick: bool, config_path, progress: bool) -> None:
    """Run ``exp`` writing every file of the run into ``folder``."""
    (folder / "config.json").write_text(json.dumps({"experiment": exp.name, "quick": quick, **config}, indent=1))
    if config_path is not None:
        shutil.copy(config_path, folder / "config.toml")
    if progress:
        print(f"{exp.name}: {exp.title}; expected run time about "
              f"{'under a minute' if quick else f'{exp.expected_minutes:g} minutes'}")
    load_start = load_average()
    start, cpu = time.perf_counter(), time.process_time()
    finding = exp.run(config, folder, progress)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    for table, rows in finding.tables.items():
        if rows:
            write_csv(folder / f"{table}.csv", rows)
    meta = {"experiment": exp.name, "title": exp.title, "reproduces": exp.reproduces, "quick": quick,
            "seconds": seconds, "cpu_seconds": cpu, "cpu_count": os.cpu_count(),
            "load_average_start": load_start, "load_average_end": load_average(),
            "threads": {v: os.environ.get(v) for v in _THREAD_VARIABLES}, "shspec_version": __version__,
            "numpy": np.__version__, "python": platform.python_version(), "machine": platform.platform(),
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"), "numbers": finding.numbers}
    (folder / "meta.json").write_text(json.dumps(meta, indent=1, default=float))
    text = experiment_markdown(exp.name, exp.title, exp.reproduces, quick, seconds, __version__, finding.summary,
                               finding.figures, finding.tables, config, cpu_seconds=cpu,
                               load=(meta["load_average_start"], meta["load_average_end"]))
    (folder / "report.md").write_text(text)
    if progress:
        print(f"{exp.name}: done in {seconds:.1f} s")
