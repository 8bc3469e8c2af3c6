"""Episode specification: what one episode of any fdia_env environment is."""

from __future__ import annotations

from dataclasses import dataclass

from fdia_env._validation import check_choice, check_int

OBJECTIVES = ("trace", "logdet")
REWARD_MODES = ("terminal", "shaped", "per_step")
DYNAMICS = ("expected", "sampled")
# clean steps run from the prior before the window (the literature's attack step K is 100); the
# warm-up is stepped one by one at every reset, so an unbounded one would hang the env
MAX_WARMUP = 10_000


@dataclass(frozen=True)
class EpisodeSpec:
    """How an episode runs.

    Attributes:
        horizon: Number of attack-window steps N (the agents act once per step), >= 1.
        warmup: ``"steady"`` to start the window with the filter in steady state (all sensors),
            or the number of unattacked steps to run from the system's prior first
            (0..``MAX_WARMUP``).
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
        check_int("horizon", self.horizon, minimum=1)
        if not (isinstance(self.warmup, str) and self.warmup == "steady"):
            if isinstance(self.warmup, str):
                raise ValueError(f"warmup must be 'steady' or an integer, got {self.warmup!r}")
            check_int("warmup", self.warmup, minimum=0, maximum=MAX_WARMUP)
        check_choice("objective", self.objective, OBJECTIVES)
        check_choice("reward_mode", self.reward_mode, REWARD_MODES)
        check_choice("dynamics", self.dynamics, DYNAMICS)
        if self.dynamics == "sampled" and self.objective != "trace":
            raise ValueError(
                "objective='logdet' is only defined for dynamics='expected': a single sampled "
                "error has no log-determinant; use objective='trace' with dynamics='sampled'"
            )
