"""Run folders: naming, creation, resume lookup, config.json and atomic writes.

A run folder is ``<runs_root>/<env>-<algo>-s<seed>-<YYYYmmdd-HHMMSS>`` and holds
``config.json``, ``checkpoints/``, ``tb/`` (TensorBoard), ``evaluations.jsonl``,
``scores.json`` and ``learning_curve.png``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import time
import typing
from collections.abc import Callable, Iterable
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
        "run.verbose",
        "run.device",
        "run.torch_threads",
    }
)


def atomic_write(path: Path, write: Callable[[IO[bytes]], Any]) -> Path:
    """Write ``path`` through a temporary file in the same folder, then ``os.replace`` it.

    A reader (or a resume after a crash) sees either the old file or the complete new one.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


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


def run_prefix(env: str, algo: str, seed: int) -> str:
    """``<env>-<algo>-s<seed>`` (the run folder name without its time)."""
    safe_env = env.replace("/", "_")
    return f"{safe_env}-{algo}-s{seed}"


def latest_run(runs_root: Path, prefix: str) -> Path | None:
    """The most recent ``<runs_root>/<prefix>-<time>`` folder, or None."""
    found = sorted(p for p in Path(runs_root).glob(f"{prefix}-*") if p.is_dir())
    return found[-1] if found else None


def prepare_run_dir(
    runs_root: Path, run_dir: Path | None, prefix: str, resume: bool
) -> tuple[Path, bool]:
    """The run folder and whether it continues an existing run.

    New run: ``run_dir`` or ``<runs_root>/<prefix>-<time>``, which must not exist. Resume:
    ``run_dir`` or the latest ``<prefix>-*`` folder, which must hold a config.json.

    Raises:
        FileExistsError: A new run's folder exists already.
        ValueError: Nothing to resume.
    """
    if resume:
        path = Path(run_dir) if run_dir is not None else latest_run(runs_root, prefix)
        if path is None:
            raise ValueError(f"nothing to resume: no run folder {Path(runs_root) / prefix}-*")
        if not (path / "config.json").is_file():
            raise ValueError(f"nothing to resume in {path}: it has no config.json")
        return path, True
    if run_dir is None:
        run_dir = Path(runs_root) / f"{prefix}-{time.strftime('%Y%m%d-%H%M%S')}"
    path = Path(run_dir)
    if path.exists():
        raise FileExistsError(
            f"run folder {path} exists; pass --resume to continue it, or choose another --run-dir"
        )
    path.mkdir(parents=True)
    return path, False


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines file ([] if missing)."""
    if not Path(path).is_file():
        return []
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def write_jsonl(path: Path, records: Iterable[dict[str, Any]]) -> Path:
    """Atomically write ``records`` as JSON lines."""
    text = "".join(json.dumps(r, default=_json_default) + "\n" for r in records)
    return atomic_write(path, lambda fh: fh.write(text.encode()))
