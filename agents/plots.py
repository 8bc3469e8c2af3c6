"""Learning curves with the analytic optimum drawn as a horizontal line (matplotlib, Agg)."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from agents.runs import atomic_write


def save_figure(fig: Any, path: Path, dpi: int = 120) -> Path:
    """Lay ``fig`` out, write it to ``path`` as a PNG (atomically) and close it; return ``path``."""
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return atomic_write(path, lambda fh: fh.write(buf.getvalue()))


def _finish(ax: Any, path: Path, labels: tuple[str, str, str], legend: str) -> Path:
    """Label ``ax`` (x label, y label, title), grid and legend it, and save its figure."""
    xlabel, ylabel, title = labels
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc=legend)
    return save_figure(ax.figure, path)


def learning_curve(
    path: Path,
    history: Sequence[dict[str, Any]],
    reference: float | None,
    reference_name: str | None,
    title: str,
) -> Path:
    """Evaluation mean return (95 % CI band) against training steps, and the reference line.

    Args:
        path: PNG to write (atomically).
        history: Records with ``timesteps``, ``mean`` and ``ci95`` (None for no interval).
        reference: The analytic optimum (None: no line).
        reference_name: Its label.
        title: Figure title.
    """
    _, ax = plt.subplots(figsize=(7, 4))
    steps = [h["timesteps"] for h in history]
    mean = [h["mean"] for h in history]
    half = [h["ci95"] or 0.0 for h in history]
    if history:
        ax.plot(steps, mean, marker="o", ms=3, label="learned policy (evaluation)")
        if any(half):  # deterministic evaluations have no interval to draw
            lo = [m - c for m, c in zip(mean, half, strict=True)]
            hi = [m + c for m, c in zip(mean, half, strict=True)]
            ax.fill_between(steps, lo, hi, alpha=0.25, label="95% CI")
    if reference is not None:
        ax.axhline(reference, color="k", ls="--", label=f"{reference_name} = {reference:.6g}")
    return _finish(ax, path, ("environment steps", "episode return", title), "lower right")


def exploitability_curve(
    path: Path, history: Sequence[dict[str, Any]], value: float, title: str
) -> Path:
    """NashConv and each side's exploitability per iteration; 0 (the equilibrium) as a line."""
    _, ax = plt.subplots(figsize=(7, 4))
    it = [h["iteration"] for h in history]
    for key, label in (
        ("nash_conv", "NashConv"),
        ("defender", "defender exploitability"),
        ("attacker", "attacker exploitability"),
    ):
        ax.plot(it, [h[key] for h in history], marker="o", ms=3, label=label)
    ax.axhline(0.0, color="k", ls="--", label="equilibrium (LP) = 0")
    ax.axhline(0.01 * abs(value), color="grey", ls=":", label=f"1% of the value {value:.4g}")
    labels = ("iteration", "exploitability (payoff units)", title)
    return _finish(ax, path, labels, "upper right")
