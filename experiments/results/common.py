"""Helpers shared by the result tables: the mean with its interval, and the JSON record."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluate import t_interval


def mean_ci95(values: Sequence[float]) -> tuple[float, float]:
    """Mean and the half-width of its two-sided 95 % Student-t confidence interval.

    Args:
        values: One figure per seed (or per instance); at least one.

    Returns:
        ``(mean, half_width)``; the half-width is ``nan`` for a single value.

    Raises:
        ValueError: For no values or a non-finite one.
    """
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"values must be a non-empty 1-d sequence, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"values must be finite, got {x.tolist()}")
    # the library's interval (the one that evaluate() reports), so tables and runs agree
    return float(x.mean()), t_interval(x, confidence=0.95)


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write a table's rows as JSON (numpy scalars converted), creating the folder."""
    path.parent.mkdir(parents=True, exist_ok=True)

    def plain(v: Any) -> Any:
        if isinstance(v, np.generic):
            return v.item()
        if isinstance(v, np.ndarray):
            return v.tolist()
        raise TypeError(f"cannot write {type(v).__name__} to JSON")

    path.write_text(json.dumps(rows, indent=1, default=plain) + "\n")
