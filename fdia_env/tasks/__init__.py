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
live outside the library, in ``baselines``).
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Mapping
from functools import cache
from importlib import resources
from types import MappingProxyType
from typing import Any

from fdia_env.tasks.catalog import SPECS, TaskSpec
from fdia_env.tasks.task import DIFFICULTIES, FAMILIES, PLAYERS, References, Task

REFERENCES_FILE = "references.json"


@cache
def stored_references() -> Mapping[str, Mapping[str, Any]]:
    """Task name → the JSON form of its stored references (``references.json``)."""
    text = resources.files(__package__).joinpath(REFERENCES_FILE).read_text(encoding="utf-8")
    return MappingProxyType(json.loads(text))


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


def _tasks() -> dict[str, Task]:
    stored = stored_references()
    return {
        spec.name: build(spec, References.from_dict(stored[spec.name]))
        for spec in SPECS
        if spec.name in stored
    }


TASKS: Mapping[str, Task] = MappingProxyType(_tasks())
"""Task name → :class:`Task`, for every defined task with stored references."""


def pending() -> list[str]:
    """Names of defined tasks that have no stored references yet (none in a release)."""
    return [spec.name for spec in SPECS if spec.name not in TASKS]


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
    if not isinstance(name, str) or name not in TASKS:
        raise ValueError(_unknown(name, list(TASKS)))
    return TASKS[name]


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
        for t in TASKS.values()
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
    "Task",
    "TaskSpec",
    "get",
    "names",
    "pending",
    "spec",
]
