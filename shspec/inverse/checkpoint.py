"""HDF5 checkpoints of a running fit, and the result file of a finished one.

A checkpoint holds the finished starts and the running one (its stage, the parameters at the stage's start, the
optimizer's state after its last completed iteration and the history), plus what the fit means
(:func:`fingerprint`: the options that change a start, the model, the starting point given) and the target itself
(eigenvalues, errors, area).  Resuming refuses another fit and says what differs; it compares the target to round-off
(:data:`TARGET_RTOL`; a computed target such as the built-in blob may move by a few ulps with the machine or library
versions, and that is not another fit) and continues the running start from that state, on the checkpoint's own
target: the optimizers are deterministic, so the result is the one of an uninterrupted run.  Files are written
atomically (:mod:`shspec.core.atomic`: a temporary file, fsynced, renamed), so a crash while writing never leaves a
truncated checkpoint; and every file carries a BLAKE2b checksum of all its datasets and attributes, checked on
reading, so a damaged file is refused by name instead of silently changing a resumed fit.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import h5py
import numpy as np
import scipy

from .._version import __version__
from ..core.atomic import write_hdf5
from ..errors import CheckpointError
from ..spectral_model import SpectralModel
from .target import Target
from .options import FitOptions
from .problem import StartProgress
from .results import StartResult

__all__ = ["fingerprint", "save_checkpoint", "load_checkpoint", "describe_checkpoint", "claim_checkpoint",
           "save_result", "load_result_summary", "TARGET_RTOL", "CHECKPOINT_FORMAT"]

#: Format version of checkpoints and result files (2: the target spectrum is stored, not hashed; 3: every start
#: carries its work, :mod:`~shspec.inverse.race`; 4: the fingerprint is stored in words, with the target's errors
#: and area).
CHECKPOINT_FORMAT = 4

#: Largest difference between a checkpoint's target (eigenvalues, errors, area) and the resuming fit's, relative to
#: its largest value, that still counts as the same target (round-off of how the target was computed).
TARGET_RTOL = 1e-12

#: Options that do not change the computation of a start, left out of the fingerprint (a checkpoint can be
#: continued with more starts, or with every start after a fit that stopped at a success; its finished
#: starts ran to their end, whatever the race).
_IGNORED = ("checkpoint_every", "checkpoint_path", "progress", "starts", "stop_at_success", "race")


def options_dict(options: FitOptions) -> dict:
    """The options as a JSON-ready dict (stages as dicts)."""
    out = dataclasses.asdict(options)
    out["schedule"] = None if options.schedule is None else [dataclasses.asdict(s) for s in options.schedule]
    return out


def fingerprint(options: FitOptions, target: Target, model: SpectralModel, init=None) -> dict:
    """What a fit's results mean, bar the target's values: ``{name: JSON-ready value}`` with the options that change
    a start (every one but bookkeeping and the number of starts and their race), the model
    (:meth:`~shspec.spectral_model.SpectralModel.identity`), the size of the target, whether it has errors and a
    known area, and a hash of the starting point ``init`` (nparams,) if one was given.

    The target's eigenvalues, errors and area are stored beside it and compared by :func:`load_checkpoint` to
    round-off: a hash would refuse a target that moved by an ulp."""
    fp = {f"option {k}": v for k, v in options_dict(options).items() if k not in _IGNORED}
    fp["model"] = model.identity()
    fp["target eigenvalues"] = int(target.numeig)
    fp["target errors"] = "given" if target.errors is not None else "none (exact)"
    fp["target area"] = "known" if target.area is not None else "estimated"
    fp["starting point"] = ("none" if init is None else "given, sha256 "
                            + hashlib.sha256(np.ascontiguousarray(init, dtype=float).tobytes()).hexdigest()[:16])
    # through JSON, as it is stored: tuples become lists, and a fingerprint compares equal to its stored copy
    return json.loads(json.dumps(fp, sort_keys=True))


def _write_start(group: h5py.Group, r: StartResult) -> None:
    for name in ("params", "history", "eigenvalues"):
        group.create_dataset(name, data=getattr(r, name))
    for name in ("index", "energy", "relative_residual", "iterations", "seconds", "status", "success", "work"):
        group.attrs[name] = getattr(r, name)


def _read_start(group: h5py.Group) -> StartResult:
    a = group.attrs
    return StartResult(index=int(a["index"]), params=group["params"][()], energy=float(a["energy"]),
                       relative_residual=float(a["relative_residual"]), iterations=int(a["iterations"]),
                       seconds=float(a["seconds"]), status=str(a["status"]), history=group["history"][()],
                       eigenvalues=group["eigenvalues"][()], success=bool(a["success"]), work=float(a["work"]))


def _content_checksum(f: h5py.File) -> str:
    """BLAKE2b over every dataset (name, dtype, shape, bytes) and attribute (name, value) but the checksum itself."""
    h = hashlib.blake2b(digest_size=32)

    def feed(name, attrs):
        for key in sorted(attrs):
            if key != "checksum":
                h.update(f"{name}@{key}={np.asarray(attrs[key]).tolist()!r};".encode())

    feed("/", f.attrs)
    names = []
    f.visit(names.append)
    for name in sorted(names):
        obj = f[name]
        feed(name, obj.attrs)
        if isinstance(obj, h5py.Dataset):
            data = np.ascontiguousarray(obj[()])
            h.update(f"{name}:{data.dtype.str}:{data.shape};".encode())
            h.update(data.tobytes())
    return h.hexdigest()


def _atomic(path: Path, write) -> None:
    """Write an HDF5 file through ``write(f)`` atomically (:func:`shspec.core.atomic.write_hdf5`), with its checksum;
    a full disk or a read-only folder is one CheckpointError naming the file (the previous one intact)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CheckpointError(f"cannot write {path}: cannot create its folder: {exc.strerror or exc}") from exc
    def fill(f):
        write(f)
        f.attrs["checksum"] = _content_checksum(f)

    write_hdf5(path, fill, error=CheckpointError)


def _open_checked(path, what: str) -> h5py.File:
    """The HDF5 file ``path`` opened for reading after its checksum was verified."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise CheckpointError(f"cannot read the {what} {path}: {exc}") from exc
    try:
        stored = f.attrs.get("checksum")
        if stored is None:
            raise CheckpointError(f"the {what} {path} has no checksum: not a complete shspec file")
        if _content_checksum(f) != stored:
            raise CheckpointError(f"the {what} {path} is damaged: its checksum does not match its content")
    except CheckpointError:
        f.close()
        raise
    except Exception as exc:  # h5py raises many kinds on damaged files; every one means the same here
        f.close()
        raise CheckpointError(f"the {what} {path} is damaged: {exc}") from exc
    return f


def save_checkpoint(path, fp: dict, finished: list, progress, target: Target) -> None:
    """Write a checkpoint: the fingerprint (:func:`fingerprint`), the target (eigenvalues, errors, area), the
    finished starts and the running start's progress (or None), as of its
    :meth:`~shspec.inverse.problem.StartProgress.resume_point`."""
    progress = None if progress is None else progress.resume_point()

    def write(f):
        f.attrs["format"] = CHECKPOINT_FORMAT
        f.attrs["fingerprint"] = json.dumps(fp, sort_keys=True)
        f.create_dataset("target", data=np.asarray(target.eigenvalues, dtype=float))
        if target.errors is not None:
            f.create_dataset("target_errors", data=np.asarray(target.errors, dtype=float))
        if target.area is not None:
            f.attrs["target_area"] = float(target.area)
        g = f.create_group("finished")
        for r in finished:
            _write_start(g.create_group(str(r.index)), r)
        if progress is not None:
            c = f.create_group("current")
            c.attrs["index"], c.attrs["stage"], c.attrs["seconds"] = progress.index, progress.stage, progress.seconds
            c.attrs["status"] = progress.status
            c.attrs["work"], c.attrs["stage_work"] = progress.work, progress.stage_work
            c.create_dataset("base", data=progress.base)
            c.create_dataset("history", data=np.array(progress.history, dtype=float).reshape(-1, 3))
            if progress.state is not None:
                s = c.create_group("state")
                for key, value in progress.state.items():
                    s.create_dataset(key, data=np.asarray(value))

    _atomic(Path(path), write)


def load_checkpoint(path, fp: dict, target: Target):
    """Read a checkpoint written by :func:`save_checkpoint`: (finished starts, running progress or None, the target
    the checkpointed fit ran on — ``target`` with the checkpoint's eigenvalues, errors and area, equal to its own to
    round-off, and what a resumed fit goes on with, so that it ends as the uninterrupted one would have).

    Raises
    ------
    CheckpointError
        If the file is unreadable, of another format, or of another fit: another fingerprint (the message lists
        what differs, the checkpoint's value and this fit's), or a target whose eigenvalues, errors or area differ
        by more than :data:`TARGET_RTOL` relative to their largest.
    """
    f = _open_checked(path, "checkpoint")
    try:
        with f:
            if f.attrs.get("format") != CHECKPOINT_FORMAT:
                raise CheckpointError(f"{path} is not a shspec fit checkpoint of format {CHECKPOINT_FORMAT}")
            differences = _differences(json.loads(f.attrs["fingerprint"]), fp)
            if differences:
                raise CheckpointError(f"{path} is the checkpoint of another fit: {'; '.join(differences)} "
                                      "(checkpoint → this fit); run it as it was to resume it, or start anew")
            stored = dataclasses.replace(
                target, eigenvalues=f["target"][()],
                errors=f["target_errors"][()] if "target_errors" in f else None,
                area=float(f.attrs["target_area"]) if "target_area" in f.attrs else None)
            _check_target(path, stored, target)
            finished = sorted((_read_start(g) for g in f["finished"].values()), key=lambda r: r.index)
            progress = None
            if "current" in f:
                c = f["current"]
                state = None
                if "state" in c:
                    state = {k: v[()] for k, v in c["state"].items()}
                progress = StartProgress(index=int(c.attrs["index"]), stage=int(c.attrs["stage"]),
                                         base=c["base"][()], state=state,
                                         history=[tuple(row) for row in c["history"][()]],
                                         seconds=float(c.attrs["seconds"]), status=str(c.attrs["status"]),
                                         work=float(c.attrs["work"]), stage_work=float(c.attrs["stage_work"]))
    except CheckpointError:
        raise
    except Exception as exc:
        raise CheckpointError(f"cannot read the checkpoint {path}: {exc}") from exc
    return finished, progress, stored


def _differences(stored: dict, fp: dict) -> list[str]:
    """What differs between a checkpoint's fingerprint and a fit's, in words ("option max_iter 4 → 5")."""
    out = []
    for key in sorted(set(stored) | set(fp)):
        old, new = stored.get(key, "(absent)"), fp.get(key, "(absent)")
        if old != new:
            out.append(f"{key} {old!r} → {new!r}")
    return out


def _check_target(path, stored: Target, target: Target) -> None:
    """Refuse a checkpoint whose target (eigenvalues, errors, area) is not the resuming fit's, up to round-off."""
    for what, a, b in (("another target spectrum", stored.eigenvalues, target.eigenvalues),
                       ("other target errors", stored.errors, target.errors),
                       ("another target area", stored.area, target.area)):
        if a is None or b is None:
            continue  # whether there are errors and an area is part of the fingerprint
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        scale = max(float(np.max(np.abs(b))), float(np.finfo(float).tiny))
        worst = float(np.max(np.abs(a - b))) / scale
        if not worst <= TARGET_RTOL:  # also refuses NaN
            raise CheckpointError(f"{path} is the checkpoint of a fit to {what} (largest difference {worst:.2g} of "
                                  f"the largest value, more than the round-off {TARGET_RTOL:g}); run it as it was "
                                  "to resume it, or start anew")


def describe_checkpoint(path) -> str:
    """What a checkpoint holds, in words: the finished starts, and the running start's stage and history rows.

    Raises
    ------
    CheckpointError
        If the file is unreadable or damaged.
    """
    f = _open_checked(path, "checkpoint")
    try:
        with f:
            finished = sorted(int(k) for k in f["finished"]) if "finished" in f else []
            text = f"{len(finished)} finished start{'s' if len(finished) != 1 else ''}"
            if finished:
                text += f" ({', '.join(map(str, finished))})"
            if "current" in f:
                c = f["current"]
                text += (f"; start {int(c.attrs['index'])} running at stage {int(c.attrs['stage'])} with "
                         f"{c['history'].shape[0]} history rows")
    except Exception as exc:
        raise CheckpointError(f"cannot read the checkpoint {path}: {exc}") from exc
    return text


def claim_checkpoint(path, *, resume: bool, overwrite: bool) -> None:
    """Check, before a fit writes into a folder, that its checkpoint ``path`` is used as the user meant.

    A fit without ``resume`` must not silently replace the checkpoint of another, unfinished run: it is refused
    (saying what the checkpoint holds) unless ``overwrite``, which removes it.  With ``resume`` the checkpoint must
    exist: starting from scratch instead would hide a mistyped folder.

    Raises
    ------
    CheckpointError
        If ``resume`` and there is no checkpoint, or a checkpoint exists and neither ``resume`` nor ``overwrite``, or
        something else than a file has its name (never removed, whatever ``overwrite``).
    """
    path = Path(path)
    if resume and overwrite:
        raise CheckpointError("--resume continues the checkpoint and --overwrite discards it: give one of them")
    if path.exists() and not path.is_file():
        raise CheckpointError(f"{path} is a {'directory' if path.is_dir() else 'special file'}, not a checkpoint; a "
                              "fit writes its checkpoint there: move it out of the way, or give another output folder")
    if resume:
        if not path.is_file():
            raise CheckpointError(f"nothing to resume: there is no checkpoint {path} (a fit writes one with "
                                  "--checkpoint-every N); run without --resume to start a new fit")
        return
    if not path.exists():
        return
    if not overwrite:
        try:
            held = describe_checkpoint(path)
        except CheckpointError as exc:
            held = f"unreadable: {exc}"
        raise CheckpointError(f"{path.parent} holds the checkpoint of an earlier fit ({held}); continue it with "
                              "--resume, or discard it with --overwrite")
    try:
        path.unlink()
    except OSError as exc:
        raise CheckpointError(f"cannot remove the old checkpoint {path}: {exc.strerror or exc}") from exc


def save_result(path, result) -> Path:
    """Write a :class:`FitResult` to HDF5: options, versions, target, every start (params, history) and the
    distinct solutions.  Returns the path.

    Raises
    ------
    CheckpointError
        If the file cannot be written.

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit, load_result_summary, save_result
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), HarmonicModel(10, 2),
    ...              FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> save_result("result.h5", result).name
    'result.h5'
    >>> load_result_summary("result.h5")["model"]
    'harmonic Lb=10 La=2'
    """
    def write(f):
        f.attrs["format"] = CHECKPOINT_FORMAT
        f.attrs["model"] = result.model.describe()
        f.attrs["options"] = json.dumps(options_dict(result.options))
        f.attrs["versions"] = json.dumps({"shspec": __version__, "numpy": np.__version__, "scipy": scipy.__version__,
                                          "h5py": h5py.__version__})
        f.attrs["seconds"] = result.seconds
        f.attrs["interrupted"] = result.interrupted
        t = f.create_group("target")
        t.attrs["name"], t.attrs["source"] = result.target.name, result.target.source
        t.create_dataset("eigenvalues", data=result.target.eigenvalues)
        if result.target.area is not None:
            t.attrs["area"] = result.target.area
        if result.target.truth is not None:
            t.create_dataset("truth", data=result.target.truth.coefficients)
        samples = result.target.factor_samples()
        if samples is not None:
            t.create_dataset("factors", data=samples[2])
        g = f.create_group("starts")
        for r in result.starts:
            _write_start(g.create_group(str(r.index)), r)
        f.create_dataset("solutions", data=np.asarray(result.solutions, dtype=np.int64))
        f.create_dataset("solution", data=result.best.params)

    path = Path(path)
    _atomic(path, write)
    return path


def load_result_summary(path) -> dict:
    """The main fields of a result file: model (its description), options, solution (params), target eigenvalues
    and starts (list of StartResult, in order of their index).

    Raises
    ------
    CheckpointError
        If the file cannot be read or is damaged (its checksum does not match).

    Examples
    --------
    >>> from shspec import HarmonicModel
    >>> from shspec.fitting import blob_factor, harmonic_target
    >>> from shspec.inverse import FitOptions, fit, load_result_summary, save_result
    >>> result = fit(harmonic_target(blob_factor().truncated(2), 10, 16), HarmonicModel(10, 2),
    ...              FitOptions(starts=1, max_iter=20, basin_hops=0, progress=False))
    >>> stored = load_result_summary(save_result("result.h5", result))
    >>> sorted(stored), (stored["solution"] == result.best.params).all()
    (['model', 'options', 'solution', 'starts', 'target'], True)
    """
    f = _open_checked(path, "result file")
    try:
        with f:
            return {"model": str(f.attrs["model"]), "options": json.loads(f.attrs["options"]),
                    "solution": f["solution"][()], "target": f["target/eigenvalues"][()],
                    "starts": sorted((_read_start(g) for g in f["starts"].values()), key=lambda r: r.index)}
    except Exception as exc:
        raise CheckpointError(f"cannot read the result file {path}: {exc}") from exc
