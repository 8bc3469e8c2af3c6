"""Renderers for the environments: a text line and a matplotlib picture."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from fdia_env.envs.parallel import FdiaParallelEnv


def render_ansi(env: FdiaParallelEnv) -> str:
    """``step k/N  attacked: z1, z2  Φ(trace) = 0.031279``."""
    sim = env.sim
    effect = env._last_effect
    if effect is None:
        attacked = "-"
    else:
        names = [s.name or f"z{i + 1}" for i, s in enumerate(env.system.sensors)]
        attacked = ", ".join(n for i, n in enumerate(names) if effect.attacked >> i & 1) or "none"
    return (
        f"step {sim.k}/{env.spec.horizon}  attacked: {attacked}  "
        f"Φ({env.spec.objective}) = {sim.phi[-1]:.6g}\n"
    )


def render_rgb(env: FdiaParallelEnv) -> np.ndarray:
    """Φ over the window so far (left) and the position/velocity error ellipse (right)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sim = env.sim
    fig = Figure(figsize=(8, 3.2), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax_phi, ax_ell = fig.subplots(1, 2)
    ax_phi.plot(range(len(sim.phi)), sim.phi, marker="o")
    ax_phi.set_xlabel("window step")
    ax_phi.set_ylabel(f"Φ ({env.spec.objective})")
    ax_phi.set_xlim(0, env.spec.horizon)
    for label, cov, style in (("start", sim.P_start, "--"), ("now", sim.M, "-")):
        xy = _ellipse(cov[:2, :2])
        ax_ell.plot(xy[0], xy[1], style, label=label)
    ax_ell.set_xlabel("error in state 1")
    ax_ell.set_ylabel("error in state 2")
    ax_ell.legend(loc="upper right")
    ax_ell.set_title("1-σ error ellipse")
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def _ellipse(cov: np.ndarray, points: int = 100) -> np.ndarray:
    if cov.shape == (1, 1):
        cov = np.diag([cov[0, 0], cov[0, 0]])
    t = np.linspace(0, 2 * np.pi, points)
    w, v = np.linalg.eigh(cov)
    return v @ (np.sqrt(np.clip(w, 0, None))[:, None] * np.stack([np.cos(t), np.sin(t)]))
