"""Run folders: naming, creation, resume lookup, locking, config.json and atomic writes.

A run folder is ``<runs_root>/<env>-<algo>-s<seed>-<YYYYmmdd-HHMMSS>`` and holds
``config.json``, ``checkpoints/``, ``tb/`` (TensorBoard), ``evaluations.jsonl``,
``scores.json`` and ``learning_curve.png``. A new run's folder is created only once its model
has been built (so a launch with bad options leaves nothing behind); ``--resume`` picks only a
folder that holds a checkpoint.
"""

from __future__ import annotations

import dataclasses
import fcntl
import json
import os
import re
import shutil
import tempfile
import time
import typing
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

# Options that may change when a run is resumed; every other option must match config.json.
RESUMABLE = frozenset(
    {
        "total_timesteps",
        "iterations",
        "final_eval_episodes",
        "run.resume",
        "run.run_dir",
        "run.runs_root",
        "run.progress_bar",
        # how a run is executed, not what it is (absent from runs made before they existed)
        "run.backend",
        "run.num_env_runners",
        "run.envs_per_env_runner",
        "run.ray_address",
        "run.num_cpus",
        "run.sample_timeout_s",
        "run.verbose",
        "run.device",
        "run.torch_threads",
        "run.trust_checkpoint",
    }
)
# The temporary files of atomic_write: ".<name>.<8 random characters>.tmp".
TEMP_FILE = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")


def _umask() -> int:
    """The process umask (read from /proc where it can be, without changing it)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[IO[bytes]], Any]) -> Path:
    """Write ``path`` through a temporary file in the same folder, then ``os.replace`` it.

    A reader (or a resume after a crash) sees either the old file or the complete new one. The
    file gets the mode a plain ``open`` would give it (``0o666`` less the umask); a temporary
    file left by a kill is removed by :func:`remove_stale_temp_files` on the next start.

    Raises:
        OSError: When it cannot be written (a full disk, no permission), naming ``path``; the
            old file is left as it was.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise _naming(exc, path) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise _naming(exc, path) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _naming(exc: OSError, path: Path) -> OSError:
    """``exc`` as a one-line OSError that names ``path`` (the file being written)."""
    if str(path) in str(exc):
        return exc
    reason = exc.strerror or str(exc) or type(exc).__name__
    return OSError(exc.errno, f"could not write {path}: {reason}")


def write_json(path: Path, data: Any) -> Path:
    """Atomically write ``data`` as indented JSON."""
    text = json.dumps(data, indent=2, default=_json_default) + "\n"
    return atomic_write(path, lambda fh: fh.write(text.encode()))


def _json_default(obj: Any) -> Any:
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def config_dict(config: Any) -> dict[str, Any]:
    """A config dataclass as a JSON-ready dict (paths as strings, tuples as lists)."""
    return json.loads(json.dumps(dataclasses.asdict(config), default=_json_default))


def config_from_dict(cls: type, data: dict[str, Any]) -> Any:
    """Rebuild a config dataclass (nested dataclasses, paths, tuples) from :func:`config_dict`."""
    hints = typing.get_type_hints(cls, include_extras=False)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        value, hint = data[f.name], hints[f.name]
        if dataclasses.is_dataclass(hint):
            value = config_from_dict(hint, value)
        elif value is not None and (hint is Path or Path in typing.get_args(hint)):
            value = Path(value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[f.name] = value
    return cls(**kwargs)


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and k not in ("env_kwargs",):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def check_resumable(saved: dict[str, Any], given: dict[str, Any], run_dir: Path) -> None:
    """Raise if ``given`` differs from the ``saved`` config in an option that defines the run.

    Raises:
        ValueError: Listing each differing option with its saved and given value.
    """
    a, b = _flatten(saved), _flatten(given)
    diff = [
        f"{k.split('.')[-1].replace('_', '-')}: saved {a.get(k)!r}, given {b.get(k)!r}"
        for k in sorted(set(a) | set(b))
        if k not in RESUMABLE and a.get(k) != b.get(k)
    ]
    if diff:
        raise ValueError(
            f"cannot resume {run_dir}: options differ from its config.json ("
            + "; ".join(diff)
            + "); give the same options, or start a new run"
        )


def check_not_shorter(
    name: str, given: int, done: int, saved: dict[str, Any], run_dir: Path, unit: str = "steps"
) -> None:
    """Raise when a resume asks for less training than the run has done already.

    A resume continues a run up to ``given`` (``--total-timesteps`` or ``--iterations``) in
    all; below what it has done there is nothing to train and its scores and model would be
    rewritten. The run's own length (``saved[name]``) is accepted even when the last rollout
    went past it (resuming a finished run re-scores it).

    Args:
        name: The option's field name (``total_timesteps``, ``iterations``).
        given: Its value for this resume.
        done: What the saved state has done, in the same unit.
        saved: The run's saved options (config.json's ``config``).
        run_dir: The run folder (for the message).
        unit: What ``done`` counts, for the message.

    Raises:
        ValueError: Naming the option, the value given and what the run has done.
    """
    own = saved.get(name)
    floor = done if not isinstance(own, int) or isinstance(own, bool) else min(done, own)
    if given < floor:
        option = f"--{name.replace('_', '-')}"
        raise ValueError(
            f"{option} {given} is below the {done} {unit} {run_dir} has trained already: a "
            f"resume continues a run and cannot shorten it; give {option} {floor} or more, "
            "or start a new run"
        )


def run_prefix(env: str, algo: str, seed: int) -> str:
    """``<env>-<algo>-s<seed>`` (the run folder name without its time)."""
    safe_env = env.replace("/", "_")
    return f"{safe_env}-{algo}-s{seed}"


def latest_run(runs_root: Path, prefix: str, marker: str | None = None) -> Path | None:
    """The most recent ``<runs_root>/<prefix>-<time>`` folder (holding ``marker``), or None."""
    found = sorted(
        p
        for p in Path(runs_root).glob(f"{prefix}-*")
        if p.is_dir() and (marker is None or (p / marker).is_file())
    )
    return found[-1] if found else None


def resume_dir(runs_root: Path, run_dir: Path | None, prefix: str, marker: str) -> Path:
    """The run folder ``--resume`` continues: ``run_dir`` or the latest ``<prefix>-*`` one.

    Only a folder holding a checkpoint (``marker``, relative to the folder) and a config.json
    can be resumed; folders without one (a launch that failed or was killed before its first
    checkpoint) are skipped.

    Raises:
        ValueError: Nothing to resume (naming the folders looked at).
    """
    if run_dir is not None:
        path = Path(run_dir)
        if not path.is_dir():
            raise ValueError(f"nothing to resume: run folder {path} (--run-dir) does not exist")
    else:
        path = latest_run(runs_root, prefix, marker)
        if path is None:
            skipped = latest_run(runs_root, prefix)
            raise ValueError(
                f"nothing to resume: no run folder {Path(runs_root) / prefix}-* holds a checkpoint"
                f" ({marker})" + (f"; {skipped} has none" if skipped is not None else "")
            )
    for name in ("config.json", marker):
        if not (path / name).is_file():
            raise ValueError(f"nothing to resume in {path}: it has no {name}")
    return path


def new_run_dir(runs_root: Path, run_dir: Path | None, prefix: str) -> Path:
    """A new run's folder, ``run_dir`` or ``<runs_root>/<prefix>-<time>`` (not created here).

    Raises:
        FileExistsError: The folder exists already.
    """
    if run_dir is None:
        run_dir = Path(runs_root) / f"{prefix}-{time.strftime('%Y%m%d-%H%M%S')}"
    path = Path(run_dir)
    if path.exists():
        raise FileExistsError(
            f"run folder {path} exists; pass --resume to continue it, or choose another --run-dir"
        )
    return path


@contextmanager
def run_lock(run_dir: Path) -> Iterator[Path]:
    """Hold an exclusive lock on ``run_dir/.lock`` (released when the process ends, too).

    Raises:
        ValueError: When another process holds it (is training in this folder).
    """
    lock_path = Path(run_dir) / ".lock"
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise ValueError(
                f"run folder {run_dir} is in use by another process (pid {owner}); wait for it "
                "to finish or stop it first"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield lock_path
    finally:
        os.close(fd)


@contextmanager
def removed_unless(run_dir: Path, marker: str) -> Iterator[Path]:
    """Remove a new run's folder if the block raises before ``run_dir/marker`` exists.

    So a launch that fails (or is aborted) before its first checkpoint leaves nothing behind.
    """
    try:
        yield run_dir
    except BaseException:
        if not (Path(run_dir) / marker).is_file():
            shutil.rmtree(run_dir, ignore_errors=True)
        raise


def remove_stale_temp_files(run_dir: Path) -> list[Path]:
    """Remove the temporary files :func:`atomic_write` left in ``run_dir`` when killed.

    Call it only while holding :func:`run_lock` (no other writer is running then).
    """
    stale = [p for p in Path(run_dir).rglob("*.tmp") if p.is_file() and TEMP_FILE.match(p.name)]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines file ([] if missing)."""
    if not Path(path).is_file():
        return []
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def write_jsonl(path: Path, records: Iterable[dict[str, Any]]) -> Path:
    """Atomically write ``records`` as JSON lines."""
    text = "".join(json.dumps(r, default=_json_default) + "\n" for r in records)
    return atomic_write(path, lambda fh: fh.write(text.encode()))
