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
import stat
import tempfile
import time
import typing
import warnings
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


def resume_dir(
    runs_root: Path, run_dir: Path | None, prefix: str, marker: str, fresh: bool = False
) -> Path:
    """The run folder ``--resume`` continues: ``run_dir`` or the latest ``<prefix>-*`` one.

    A folder holding a checkpoint (``marker``, relative to the folder) and a config.json can be
    resumed; folders without a checkpoint (a launch that failed or was killed before its first
    checkpoint) are skipped in the search for the latest one. With ``fresh``, a run killed
    before its first checkpoint (a config.json and no ``marker``) is returned too, when
    ``run_dir`` names it or no folder of ``prefix`` holds a checkpoint: its driver starts it
    again from step 0.

    Raises:
        ValueError: Nothing to resume (naming the folders looked at).
    """
    if run_dir is not None:
        path = Path(run_dir)
        if not path.is_dir():
            raise ValueError(f"nothing to resume: run folder {path} (--run-dir) does not exist")
    else:
        path = latest_run(runs_root, prefix, marker)
        if path is None and fresh:
            path = latest_run(runs_root, prefix, "config.json")
        if path is None:
            skipped = latest_run(runs_root, prefix)
            raise ValueError(
                f"nothing to resume: no run folder {Path(runs_root) / prefix}-* holds a checkpoint"
                f" ({marker})" + (f"; {skipped} has none" if skipped is not None else "")
            )
    for name in ("config.json", marker)[: 1 if fresh else 2]:
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


LOCK = ".lock"
# What run_lock writes into the lock file: the PID of its holder (empty while it writes it).
_LOCK_CONTENT = re.compile(rb"^\d{0,20}\n?$")


def _open_lock(lock_path: Path) -> int:
    """A descriptor of ``lock_path``, created here or a plain lock file an earlier run left.

    The file is never followed through a symlink (``O_NOFOLLOW``) and an existing one is used
    only when it is a regular file with one link holding nothing but a PID: no other file is
    ever written or truncated through it.

    Raises:
        ValueError: For a ``.lock`` that is a symlink, not a regular file, has other links or
            holds anything but a PID (naming it and how to clear it).
    """
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    try:
        return os.open(lock_path, flags | os.O_CREAT | os.O_EXCL, 0o666)
    except FileExistsError:
        pass

    def refuse(why: str) -> ValueError:
        return ValueError(
            f"run folder lock {lock_path} is not a lock file written by train.py ({why}); it was "
            "not opened: remove it if no run is training in this folder"
        )

    try:
        fd = os.open(lock_path, flags)
    except OSError as exc:
        why = "a symlink" if Path(lock_path).is_symlink() else exc.strerror or str(exc)
        raise refuse(why) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise refuse("not a regular file")
        if info.st_nlink != 1:
            raise refuse(f"a file with {info.st_nlink} hard links")
        if not _LOCK_CONTENT.match(os.pread(fd, 64, 0)):
            raise refuse("it holds something other than a PID")
    except BaseException:
        os.close(fd)
        raise
    return fd


@contextmanager
def run_lock(run_dir: Path) -> Iterator[Path]:
    """Hold an exclusive lock on ``run_dir/.lock`` (released when the process ends, too).

    The lock file is created without following symlinks; one left by an earlier run (a dead
    process holds no lock) is reused only when it is a plain lock file (:func:`_open_lock`).

    Raises:
        ValueError: When another process holds it (is training in this folder), or for a
            ``.lock`` that is not a plain lock file.
    """
    lock_path = Path(run_dir) / LOCK
    fd = _open_lock(lock_path)
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


class CorruptLogLine(UserWarning):
    """A line of a JSON-lines log that is not a valid record; it was skipped."""


def read_jsonl(
    path: Path, valid: Callable[[dict[str, Any]], bool] | None = None
) -> list[dict[str, Any]]:
    """The records of a JSON-lines log ([] if missing), skipping the lines that are not records.

    A log is not a run's state: a truncated or corrupt line (a kill mid-write, a bad edit)
    is skipped with a :class:`CorruptLogLine` warning naming the file and the line, and the
    other records are kept.

    Args:
        path: The ``.jsonl`` file.
        valid: A record's check (a line that parses to a JSON object is a record when it
            returns True); None: every object.

    Raises:
        ValueError: When the file exists but cannot be read (naming it).
    """
    path = Path(path)
    if not path.is_file():
        return []
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise ValueError(f"log {path} cannot be read: {exc.strerror or exc}") from None
    records = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError as exc:
            reason = f"not JSON ({exc})"
        else:
            if isinstance(record, dict) and (valid is None or valid(record)):
                records.append(record)
                continue
            reason = "not a valid record"
        warnings.warn(f"skipped line {number} of {path}: {reason}", CorruptLogLine, stacklevel=2)
    return records


def write_jsonl(path: Path, records: Iterable[dict[str, Any]]) -> Path:
    """Atomically write ``records`` as JSON lines."""
    text = "".join(json.dumps(r, default=_json_default) + "\n" for r in records)
    return atomic_write(path, lambda fh: fh.write(text.encode()))
