"""Episode specification: what one episode of any fdia_env environment is."""

from __future__ import annotations

from dataclasses import dataclass

from fdia_env._validation import check_choice, check_int

OBJECTIVES = ("trace", "logdet")
REWARD_MODES = ("terminal", "shaped", "per_step")
DYNAMICS = ("expected", "sampled")
# Largest integer warmup. Every warmup step is a Python-level filter step (and, sampled, draws)
# at every reset; the covariance converges geometrically for a detectable system, so a longer
# warmup only reproduces ``warmup="steady"`` (the DARE solution) at a cost that grows without
# bound (the literature's attack step K is 100).
MAX_WARMUP = 10_000
# Largest attack window N. The engine tabulates per-step values of the whole window at
# construction, so a window of 10**9 steps (or 2**63) failed at the first reset or step with a
# MemoryError or an IndexError instead of naming the parameter.
MAX_HORIZON = 1_000_000


@dataclass(frozen=True)
class EpisodeSpec:
    """How an episode runs.

    Attributes:
        horizon: Number of attack-window steps N (the agents act once per step),
            ``1 <= horizon <= MAX_HORIZON`` (1 000 000).
        warmup: ``"steady"`` to start the window with the filter in steady state (all sensors),
            or the number of unattacked steps to run from the system's prior first,
            ``0 <= warmup <= MAX_WARMUP`` (10 000; beyond it use ``"steady"``).
        objective: Φ: ``"trace"`` or ``"logdet"`` of the actual error covariance.
        reward_mode: ``"terminal"`` pays Φ at the end only; ``"shaped"`` pays the per-step
            increments (their sum is Φ_N − Φ_0); ``"per_step"`` pays Φ every step.
        dynamics: ``"expected"`` uses the covariance recursions; ``"sampled"`` draws states,
            noises and biases and pays the squared estimation error (trace objective only).
    """

    horizon: int
    warmup: int | str = "steady"
    objective: str = "trace"
    reward_mode: str = "terminal"
    dynamics: str = "expected"

    def __post_init__(self) -> None:
        try:
            check_int("horizon", self.horizon, minimum=1, maximum=MAX_HORIZON)
        except ValueError as exc:
            raise ValueError(
                f"{exc}: horizon (an env's max_cycles where no horizon is given, the sensor "
                f"game's rounds) must be an integer in [1, {MAX_HORIZON}]"
            ) from None
        if not (isinstance(self.warmup, str) and self.warmup == "steady"):
            if isinstance(self.warmup, str):
                raise ValueError(f"warmup must be 'steady' or an integer, got {self.warmup!r}")
            try:
                check_int("warmup", self.warmup, minimum=0, maximum=MAX_WARMUP)
            except ValueError as exc:
                raise ValueError(
                    f"{exc}: warmup must be 'steady' or an integer in [0, {MAX_WARMUP}] "
                    "(the filter has converged long before; use warmup='steady')"
                ) from None
        check_choice("objective", self.objective, OBJECTIVES)
        check_choice("reward_mode", self.reward_mode, REWARD_MODES)
        check_choice("dynamics", self.dynamics, DYNAMICS)
        if self.dynamics == "sampled" and self.objective != "trace":
            raise ValueError(
                "objective='logdet' is only defined for dynamics='expected': a single sampled "
                "error has no log-determinant; use objective='trace' with dynamics='sampled'"
            )
