"""Stored payoff matrices of the benchmark's large sensor games (exact, computed once).

Scoring a policy in a sensor game needs the game's whole payoff matrix (its exploitability is
a best response on it). On the IEEE 118 grid building that matrix solves one 117-state Riccati
equation per defender subset, which takes minutes. The matrix is small (305 × 304 numbers), so it
is stored beside the task references (``payoffs.json`` lists each file with the game it
belongs to) and :func:`stored_payoff` hands it to the scoring code instead of rebuilding it.

A stored matrix is used only for the game it was computed for: the same scenario name, attack
power, allocation rule and subset size, and a system whose fingerprint (sums of the entries
and of their squares of F, Q, H and R) agrees to 1e-9. The file is read with
``allow_pickle=False``; its name must be a plain ``.npy`` name inside ``payoffs/`` (no
separators, no ``..``), and its SHA-256 must be the one in ``payoffs.json``. In this package's
store ``payoffs.json`` and every file must also have the SHA-256 recorded in
:mod:`fdia_env.tasks.digests`, so an edited manifest cannot vouch for a changed file. A failed
check is a :class:`~fdia_env.tasks.stored.StoredDataError` naming the file and the entry.
``python -m agents.bench payoff`` writes the files (and the digests); ``python -m agents.bench
verify`` rebuilds a stored matrix and compares it.

>>> from fdia_env import scenarios
>>> L = stored_payoff(scenarios.get("grid-ieee118"), 0.01, "independent", 1)
>>> L.shape, L.flags.writeable
((305, 304), False)
>>> stored_payoff(scenarios.get("grid-ieee118"), 0.02, "independent", 1) is None
True
"""

from __future__ import annotations

import hashlib
import io
import json
import math
from collections.abc import Mapping
from functools import cache
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from fdia_env.tasks.stored import (
    PACKAGE,
    StoredDataError,
    check_digest,
    check_payoff_manifest,
    payoff_path,
    recorded,
    write_digests,
)

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


def _is_package_store(folder: Path) -> bool:
    return Path(folder).resolve() == PACKAGE


@cache
def manifest(folder: Path | None = None) -> Mapping[str, Mapping[str, Any]]:
    """File name → the game it stores (``payoffs.json``; empty when there is none), checked.

    Raises:
        StoredDataError: Naming ``payoffs.json`` (and the entry and key) when its SHA-256 is
            not the recorded one (this package's store), an entry is malformed, or a file name
            leaves ``payoffs/``.
    """
    folder = folder or _folder()
    path = folder / MANIFEST
    package = _is_package_store(folder)
    if not path.is_file():
        if package and recorded().PAYOFF_MANIFEST is not None:
            raise StoredDataError(f"{path}: missing (its SHA-256 is recorded in digests.py)")
        return MappingProxyType({})
    data = path.read_bytes()
    if package:  # an edited manifest cannot vouch for the files it lists
        check_digest(path, data, recorded().PAYOFF_MANIFEST, "python -m agents.bench payoff")
    data = check_payoff_manifest(path, folder / FOLDER, data, None)
    return MappingProxyType(data)


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
        StoredDataError: (a ValueError) When ``payoffs.json`` is changed or malformed, or the
            file listed for this game leaves ``payoffs/``, is missing, is not the file that was
            stored (its SHA-256 differs from the manifest's or the recorded one), is no float64
            array, has another shape or holds a NaN or infinite number.
    """
    if not hasattr(scenario, "system"):
        return None
    folder = folder or _folder()
    key = game_key(scenario, power, allocation, max_subset_size)
    for name, entry in manifest(folder).items():
        if _matches(entry, key):
            return _load(folder, name, entry)
    return None


def _load(folder: Path, name: str, entry: Mapping[str, Any]) -> np.ndarray:
    """The checked, read-only matrix of the manifest entry ``name``."""
    path = payoff_path(folder / MANIFEST, folder / FOLDER, name)
    where = f"stored payoff {path} (entry {name!r} of {folder / MANIFEST})"
    if not path.is_file():
        raise StoredDataError(f"{where}: missing; rebuild it with python -m agents.bench payoff")
    data = path.read_bytes()
    if hashlib.sha256(data).hexdigest() != entry["sha256"]:
        raise StoredDataError(
            f"{where}: changed (its SHA-256 is not the one in {MANIFEST}); rebuild it with "
            "python -m agents.bench payoff"
        )
    if _is_package_store(folder):
        digest = recorded().PAYOFF_FILES.get(name)
        check_digest(path, data, digest, "python -m agents.bench payoff")
    try:
        L = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise StoredDataError(f"{where}: not a .npy array ({exc})") from None
    if not isinstance(L, np.ndarray) or L.dtype != np.float64:
        got = getattr(L, "dtype", type(L).__name__)
        raise StoredDataError(f"{where}: dtype {got}, expected float64")
    if list(L.shape) != list(entry["shape"]):
        raise StoredDataError(f"{where}: shape {L.shape}, expected {tuple(entry['shape'])}")
    if not np.isfinite(L).all():
        raise StoredDataError(f"{where}: holds NaN or infinite entries")
    L.setflags(write=False)
    return L


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
    index = dict(manifest(folder))  # a changed or malformed manifest is refused first
    path = folder / FOLDER / name
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, np.ascontiguousarray(L, dtype=np.float64), allow_pickle=False)
    index = {n: e for n, e in index.items() if n != name and not _matches(e, key)}
    index[name] = {**key, "shape": list(np.shape(L)), "sha256": sha256(path)}
    (folder / MANIFEST).write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")
    manifest.cache_clear()
    if _is_package_store(folder):
        from fdia_env.tasks import REFERENCES_PATH

        write_digests(REFERENCES_PATH, folder / MANIFEST, folder / FOLDER)
    return path
