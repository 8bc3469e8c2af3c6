"""Named benchmark tasks with certified references and a normalised score.

A task (:class:`Task`) fixes an env (Gymnasium id and kwargs), the player that is scored, the
number of episodes, and stores the reference values the project's solvers computed for it:
random play (mean and 95 % CI), the polynomial heuristics, the certified optimum (or the best
known value with its certified bound and gap), the game value for games, with the solver
versions and the date. ``task.normalise(raw)`` is the normalised score: 0 = random play,
1 = the certified optimum (docs/benchmark.md, "Normalised score").

>>> from fdia_env import tasks
>>> task = tasks.get("sparse/ch4-position-v0")
>>> task.family, task.player, task.env_id
('sparse', 'attacker', 'fdia_env/SparseAttack-v0')
>>> task.normalise(task.references.optimum.value), task.normalise(task.references.random.mean)
(1.0, 0.0)
>>> "sparse/ch4-position-v0" in tasks.names(family="sparse")
True

The references are recomputed and compared by ``python -m agents.bench verify`` (the solvers
live outside the library, in ``baselines``). ``references.json`` is checked when it is first
read (on the first use of :data:`TASKS`, :func:`get` or :func:`names`): its SHA-256 must be the
one recorded in :mod:`fdia_env.tasks.digests` and every entry well formed, else a
:class:`~fdia_env.tasks.stored.StoredDataError` names the file, the entry and the key.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from types import MappingProxyType
from typing import Any

from fdia_env.tasks.catalog import SPECS, TaskSpec
from fdia_env.tasks.stored import StoredDataError, check_references, read_stored, recorded
from fdia_env.tasks.task import DIFFICULTIES, FAMILIES, PLAYERS, References, Task

REFERENCES_FILE = "references.json"


REFERENCES_PATH = Path(__file__).resolve().with_name(REFERENCES_FILE)


@cache
def stored_references() -> Mapping[str, Mapping[str, Any]]:
    """Task name → the JSON form of its stored references (``references.json``), checked.

    Raises:
        StoredDataError: Naming the file (and the entry and key) when its SHA-256 is not the
            recorded one or an entry is malformed (a missing key, a NaN).
    """
    data = check_references(REFERENCES_PATH, read_stored(REFERENCES_PATH), recorded().REFERENCES)
    return MappingProxyType(data)


def build(spec: TaskSpec, references: References) -> Task:
    """The :class:`Task` of ``spec`` with ``references`` (its difficulty graded from them)."""
    return Task(
        name=spec.name,
        family=spec.family,
        player=spec.player,
        difficulty=references.grade(),
        env_id=spec.env_id,
        env_kwargs=spec.env_kwargs,
        module=spec.module,
        episodes=spec.episodes,
        description=spec.description,
        references=references,
        entry_point=spec.entry_point,
    )


def _build(spec: TaskSpec, data: Mapping[str, Any]) -> Task:
    try:
        return build(spec, References.from_dict(data))
    except ValueError as exc:  # an objective or metric not known, optimum == random
        raise StoredDataError(f"{REFERENCES_PATH}: entry {spec.name!r}: {exc}") from None


@cache
def _tasks() -> Mapping[str, Task]:
    stored = stored_references()
    return MappingProxyType(
        {spec.name: _build(spec, stored[spec.name]) for spec in SPECS if spec.name in stored}
    )


def __getattr__(name: str) -> Any:
    # TASKS is built on first use, so that the module imports (and the command that rewrites
    # references.json runs) even when the stored file is refused.
    if name == "TASKS":
        return _tasks()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


TASKS: Mapping[str, Task]
"""Task name → :class:`Task`, for every defined task with stored references (built on first
use from the checked ``references.json``)."""


def pending() -> list[str]:
    """Names of defined tasks that have no stored references yet (none in a release)."""
    return [spec.name for spec in SPECS if spec.name not in _tasks()]


def spec(name: str) -> TaskSpec:
    """The definition of task ``name`` (with or without stored references).

    Raises:
        ValueError: Naming ``task`` for an unknown name (listing close names).
    """
    for s in SPECS:
        if s.name == name:
            return s
    raise ValueError(_unknown(name, [s.name for s in SPECS]))


def _unknown(name: Any, known: list[str]) -> str:
    close = difflib.get_close_matches(str(name), known, n=5, cutoff=0.4)
    hint = f"; close names: {', '.join(close)}" if close else ""
    return (
        f"task must be a task name, got {name!r}{hint} "
        f"(fdia_env.tasks.names() lists all {len(known)})"
    )


def get(name: str) -> Task:
    """The task called ``name`` (``"sparse/ch4-position-v0"``).

    Raises:
        ValueError: Naming ``task`` for an unknown name, listing the closest task names.
    """
    known = _tasks()
    if not isinstance(name, str) or name not in known:
        raise ValueError(_unknown(name, list(known)))
    return known[name]


def names(difficulty: str | None = None, family: str | None = None) -> list[str]:
    """Task names, optionally only those of one ``difficulty`` and/or ``family``.

    Raises:
        ValueError: For a difficulty or family that does not exist (listing those that do).
    """
    if difficulty is not None and difficulty not in DIFFICULTIES:
        raise ValueError(f"difficulty must be one of {list(DIFFICULTIES)}, got {difficulty!r}")
    if family is not None and family not in FAMILIES:
        raise ValueError(f"family must be one of {list(FAMILIES)}, got {family!r}")
    return [
        t.name
        for t in _tasks().values()
        if (difficulty is None or t.difficulty == difficulty)
        and (family is None or t.family == family)
    ]


__all__ = [
    "DIFFICULTIES",
    "FAMILIES",
    "PLAYERS",
    "SPECS",
    "TASKS",
    "References",
    "StoredDataError",
    "Task",
    "TaskSpec",
    "get",
    "names",
    "pending",
    "spec",
]
