"""Stored payoff matrices of the benchmark's large sensor games (exact, computed once).

Scoring a policy in a sensor game needs the game's whole payoff matrix (its exploitability is
a best response on it). On the IEEE 118 grid building that matrix solves one 117-state Riccati
equation per defender subset, which takes minutes. The matrix is small (305 × 304 numbers), so it
is stored beside the task references (``payoffs.json`` lists each file with the game it
belongs to) and :func:`stored_payoff` hands it to the scoring code instead of rebuilding it.

A stored matrix is used only for the game it was computed for: the same scenario name, attack
power, allocation rule and subset size, and a system whose fingerprint (sums of the entries
and of their squares of F, Q, H and R) agrees to 1e-9. The file is read with
``allow_pickle=False`` and its SHA-256 is checked. ``python -m agents.bench payoff`` writes
the files; ``python -m agents.bench verify`` rebuilds a stored matrix and compares it.

>>> from fdia_env import scenarios
>>> L = stored_payoff(scenarios.get("grid-ieee118"), 0.01, "independent", 1)
>>> L.shape, L.flags.writeable
((305, 304), False)
>>> stored_payoff(scenarios.get("grid-ieee118"), 0.02, "independent", 1) is None
True
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from functools import cache
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

MANIFEST = "payoffs.json"
FOLDER = "payoffs"
FINGERPRINT_RTOL = 1e-9


def fingerprint(system: Any) -> list[float]:
    """Sums of the entries and of their squares of the system's F, Q, H and R (8 numbers)."""
    out = []
    for name in ("F", "Q", "H", "R"):
        a = np.asarray(getattr(system, name), dtype=np.float64)
        out += [float(a.sum()), float(np.square(a).sum())]
    return out


def game_key(scenario: Any, power: float, allocation: str, max_subset_size: int | None) -> dict:
    """The JSON description of a sensor game a stored matrix belongs to."""
    return {
        "scenario": str(getattr(scenario, "name", "")),
        "power": float(power),
        "allocation": str(allocation),
        "max_subset_size": None if max_subset_size is None else int(max_subset_size),
        "fingerprint": fingerprint(scenario.system),
    }


def _matches(entry: Mapping[str, Any], key: Mapping[str, Any]) -> bool:
    if any(entry[k] != key[k] for k in ("scenario", "allocation", "max_subset_size")):
        return False
    if not math.isclose(entry["power"], key["power"], rel_tol=1e-12):
        return False
    return all(
        math.isclose(a, b, rel_tol=FINGERPRINT_RTOL, abs_tol=1e-300)
        for a, b in zip(entry["fingerprint"], key["fingerprint"], strict=True)
    )


def _folder() -> Path:
    return Path(str(resources.files(__package__)))


@cache
def manifest(folder: Path | None = None) -> Mapping[str, Mapping[str, Any]]:
    """File name → the game it stores (``payoffs.json``; empty when there is none)."""
    path = (folder or _folder()) / MANIFEST
    if not path.is_file():
        return MappingProxyType({})
    return MappingProxyType(json.loads(path.read_text(encoding="utf-8")))


def sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def stored_payoff(
    scenario: Any,
    power: float,
    allocation: str,
    max_subset_size: int | None,
    folder: Path | None = None,
) -> np.ndarray | None:
    """The stored payoff matrix of this sensor game (read-only), or None when none is stored.

    Args:
        scenario: The game's :class:`~fdia_env.scenarios.Scenario`.
        power: Attack power a².
        allocation: ``"independent"`` or ``"dependent"``.
        max_subset_size: The game's k (None: every subset).
        folder: Where ``payoffs.json`` and the files are (default: this package).

    Raises:
        ValueError: When the file listed for this game is missing, is not the file that was
            stored (its SHA-256 differs) or has another shape.
    """
    if not hasattr(scenario, "system"):
        return None
    folder = folder or _folder()
    key = game_key(scenario, power, allocation, max_subset_size)
    for name, entry in manifest(folder).items():
        if not _matches(entry, key):
            continue
        path = folder / FOLDER / name
        if not path.is_file() or sha256(path) != entry["sha256"]:
            raise ValueError(
                f"stored payoff {path}: missing or changed (its SHA-256 is not the one in "
                f"{MANIFEST}); rebuild it with python -m agents.bench payoff"
            )
        L = np.load(path, allow_pickle=False)
        if list(L.shape) != list(entry["shape"]) or L.dtype != np.float64:
            raise ValueError(f"stored payoff {path}: shape {L.shape}, expected {entry['shape']}")
        L.setflags(write=False)
        return L
    return None


def write_payoff(
    L: np.ndarray,
    scenario: Any,
    power: float,
    allocation: str,
    max_subset_size: int | None,
    folder: Path | None = None,
) -> Path:
    """Store ``L`` as the payoff of this sensor game (replacing a stored one); its path."""
    folder = folder or _folder()
    key = game_key(scenario, power, allocation, max_subset_size)
    k = "all" if max_subset_size is None else f"k{int(max_subset_size)}"
    name = f"{key['scenario'] or 'game'}-{allocation}-{k}-a{float(power):g}.npy"
    path = folder / FOLDER / name
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, np.ascontiguousarray(L, dtype=np.float64), allow_pickle=False)
    index = dict(manifest(folder))
    index = {n: e for n, e in index.items() if n != name and not _matches(e, key)}
    index[name] = {**key, "shape": list(np.shape(L)), "sha256": sha256(path)}
    (folder / MANIFEST).write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")
    manifest.cache_clear()
    return path
