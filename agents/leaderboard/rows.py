"""The leaderboard's rows file: read, merge, written atomically, and which runs it already holds.

``--out`` is a JSON file ``{"rows": [...]}``, one row per (task, learner, seed): the score of a
trained run (``status`` ``"ok"``; rows written before the status existed count as ok) or a run
that failed (``status`` ``"failed"`` with its ``error``). The file is replaced atomically after
every run, so a killed runner leaves the rows of every finished run and a rerun skips them
(:func:`is_done`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

OK, FAILED = "ok", "failed"


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows written so far ([] when the file does not exist).

    Raises:
        ValueError: Naming ``--out`` when the file is not a rows file ``{"rows": [...]}``.
    """
    path = Path(path)
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f'--out {path}: not a rows file {{"rows": [...]}} ({exc})') from None
    if not isinstance(data, dict) or not isinstance(data.get("rows", []), list):
        raise ValueError(f'--out {path}: not a rows file {{"rows": [...]}}')
    return list(data.get("rows", []))


def key(row: dict[str, Any]) -> tuple[str, str, int]:
    """A row's run: (task, method, seed)."""
    return row["task"], row["method"], row["seed"]


def merge_rows(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``old`` with the rows of the same (task, method, seed) as a new one replaced."""
    keys = {key(r) for r in new}
    return [r for r in old if key(r) not in keys] + new


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the rows as ``{"rows": [...]}``, atomically (a reader sees the old or the new file).

    Raises:
        OSError: When the file cannot be written (naming it); the old file is left as it was.
    """
    from agents.runs import atomic_write

    text = json.dumps({"rows": rows}, indent=1) + "\n"
    atomic_write(Path(path), lambda fh: fh.write(text.encode("utf-8")))


def failed(row: dict[str, Any]) -> bool:
    """Whether ``row`` is a run that failed."""
    return row.get("status", OK) == FAILED


def as_json(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples become lists), for comparisons with rows."""
    return json.loads(json.dumps(value))


def is_done(
    row: dict[str, Any],
    run: tuple[str, str, int],
    timesteps: int,
    hyperparameters: dict[str, Any],
    episodes: int | None = None,
) -> bool:
    """Whether ``row`` is a finished run of ``run`` (task, method, seed) with these settings.

    The same training budget and hyperparameters (as the row records them) and, when
    ``episodes`` is given, the same number of evaluation episodes; a failed row is not done.

    >>> row = {"task": "t", "method": "PPO", "seed": 0, "timesteps": 64, "hyperparameters": {}}
    >>> is_done(row, ("t", "PPO", 0), 64, {}), is_done(row, ("t", "PPO", 0), 128, {})
    (True, False)
    >>> is_done({**row, "status": "failed"}, ("t", "PPO", 0), 64, {})
    False
    """
    return (
        not failed(row)
        and key(row) == run
        and row.get("timesteps") == timesteps
        and as_json(row.get("hyperparameters", {})) == as_json(hyperparameters)
        and (episodes is None or row.get("episodes") == episodes)
    )
