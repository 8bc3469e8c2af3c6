"""Multi-shot (continuous) attack: bias covariances over a window (docs/math.md §2.1–2.2).

The filter is in steady state at K−1 with every sensor and keeps its steady gain W; biases
``Σ[K+j]`` are injected at ``j = 0..N−1`` (``N = horizon`` steps; docs/math.md's window K..K+N' has
``N' = N − 1``). With ``B = (I − W H) F`` and ``D_m = B^m W`` the extra MSE is
``A[K+m] = Σ_{j≤m} D_{m−j} Σ[K+j] D_{m−j}'``, so the objective with time weights α_m
(``Σ α_m = 1``) is linear in the Σ's:

    Σ_m α_m tr A[K+m] = Σ_j tr(C_j Σ[K+j]),   C_j = Σ_{m=j..N−1} α_m D_{m−j}' D_{m−j}.

With ``C̃_j = Ω^{-1/2} C_j Ω^{-1/2}``:

- ``power_mode="budget"`` (``Σ_j tr(Ω Σ[K+j]) = a²``): all the power at the step and direction of
  the largest eigenvalue over all ``C̃_j`` (docs/math.md §2.2); with equal weights that is step 0,
  since ``C_0 ⪰ C_j``.
- ``power_mode="per_step"`` (``tr(Ω Σ[K+j]) = a²`` every step): the problems separate; each step
  goes along the top eigenvector of its own ``C̃_j``.

:func:`recursion_objective` evaluates any plan by the covariance recursion itself
(:func:`~fdia_env.kalman.actual_covariance_step`), the cross-check of the closed form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baselines._inputs import resolve_system
from baselines.covariance.problem import make_problem
from baselines.covariance.trace import top_eigenvector
from fdia_env._validation import (
    as_float_array,
    as_vector,
    check_choice,
    check_finite,
    check_int,
    check_psd,
)
from fdia_env.kalman import actual_covariance_step, steady_state
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

if TYPE_CHECKING:
    from baselines.covariance.policy import CovariancePolicy

POWER_MODES = ("budget", "per_step")


@dataclass(frozen=True, eq=False)
class MultiShotResult:
    """Per-step bias covariances of a multi-shot attack and their objective.

    Attributes:
        sigmas: (N, nz, nz) ``Σ[K+j]`` for ``j = 0..N−1`` (zero where nothing is injected).
        value: ``Σ_m α_m tr(P[K|K] + A[K+m])``, i.e. ``tr P + extra``.
        extra: ``Σ_m α_m tr A[K+m] = Σ_j tr(C_j Σ[K+j])``.
        weights: (N,) time weights α_m.
        coefficients: (N, nz, nz) the ``C_j``.
        gains: (N,) ``λ_max(C̃_j)`` per step.
        step: ``"budget"`` mode: the step that receives all the power; ``None`` per step.
        power_mode: ``"budget"`` or ``"per_step"``.
        budget: The power a².
    """

    sigmas: np.ndarray = field(repr=False)
    value: float
    extra: float
    weights: np.ndarray = field(repr=False)
    coefficients: np.ndarray = field(repr=False)
    gains: np.ndarray = field(repr=False)
    step: int | None
    power_mode: str
    budget: float

    @property
    def horizon(self) -> int:
        """Number of steps N."""
        return self.sigmas.shape[0]

    def policy(self, source: Any) -> CovariancePolicy:
        """The policy that plays ``sigmas`` in ``source``'s env (see :class:`CovariancePolicy`)."""
        from baselines.covariance.policy import CovariancePolicy

        return CovariancePolicy(source, self.sigmas, horizon=self.horizon)


# attacked steps of one plan: (N, nz, nz) coefficient matrices are built and stored
MAX_HORIZON = 10_000


def check_weights(weights: np.ndarray | None, horizon: int) -> np.ndarray:
    """Time weights α (default equal) as a read-only (N,) array; ``ValueError`` naming weights."""
    if weights is None:
        alpha = np.full(horizon, 1.0 / horizon)
        alpha.setflags(write=False)
        return alpha
    alpha = as_vector("weights", weights, horizon)
    if np.any(alpha < 0.0) or abs(float(alpha.sum()) - 1.0) > 1e-9:
        raise ValueError(
            f"weights must be non-negative and sum to 1 (docs/math.md §2.2), got {alpha.tolist()} "
            f"(sum {float(alpha.sum())!r})"
        )
    return alpha


def coefficient_matrices(
    system: LinearSystem, weights: np.ndarray, W: np.ndarray | None = None
) -> np.ndarray:
    """(N, nz, nz) ``C_j = Σ_{m=j..N−1} α_m D_{m−j}' D_{m−j}``, ``D_m = B^m W``, steady gain W."""
    if W is None:
        W = steady_state(system)[2]
    N = weights.shape[0]
    B = (np.eye(system.n) - W @ system.H) @ system.F  # B = (I − W H) F
    D = np.empty((N, *W.shape))
    D[0] = W
    for m in range(1, N):
        D[m] = B @ D[m - 1]
    G = np.swapaxes(D, -1, -2) @ D  # D_m' D_m
    C = np.zeros((N, system.nz, system.nz))
    for j in range(N):
        C[j] = np.tensordot(weights[j:], G[: N - j], axes=1)  # Σ_{m=j..N−1} α_m G_{m−j}
    return 0.5 * (C + np.swapaxes(C, -1, -2))


def multi_shot(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None,
    horizon: int,
    weights: np.ndarray | None = None,
    *,
    weight: np.ndarray | None = None,
    power_mode: str = "budget",
) -> MultiShotResult:
    """Trace-optimal bias covariances over ``horizon`` steps (docs/math.md §2.2, multi-shot).

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        power: a² > 0 (default: the scenario's): the total over the window in ``"budget"``
            mode, every step's in ``"per_step"`` mode.
        horizon: Number of attacked steps N, 1..``MAX_HORIZON`` (steps K..K+N−1).
        weights: (N,) time weights α_m ≥ 0 summing to 1 (default equal); ``α = e_{N−1}``
            scores only the last step, like the env's terminal reward.
        weight: (nz, nz) power weighting Ω (default :func:`~fdia_env.systems.power_weight`).
        power_mode: ``"budget"`` or ``"per_step"``.

    Raises:
        ValueError: Naming the parameter: a bad power, horizon, weights, weight or power mode.

    Example:
        >>> result = multi_shot("ch2-position", 3000.0, horizon=5)
        >>> result.step, round(result.value, 2)
        (0, 174.16)
    """
    check_choice("power_mode", power_mode, POWER_MODES)
    horizon = check_int("horizon", horizon, minimum=1, maximum=MAX_HORIZON)
    alpha = check_weights(weights, horizon)
    problem = make_problem(system_or_scenario, power, weight)
    C = coefficient_matrices(problem.system, alpha, problem.W)
    Ct = problem.weight_inv_half @ C @ problem.weight_inv_half  # C̃_j
    tops = [top_eigenvector(c) for c in Ct]
    gains = np.array([g for g, _ in tops])
    sigmas = np.zeros_like(C)
    steps = range(horizon) if power_mode == "per_step" else [int(np.argmax(gains))]
    for j in steps:
        sigmas[j] = problem.from_tilde(problem.power * np.outer(tops[j][1], tops[j][1]))
    extra = float(np.einsum("jab,jab->", C, sigmas))  # Σ_j tr(C_j Σ_j), both symmetric
    for arr in (sigmas, C, gains):
        arr.setflags(write=False)
    return MultiShotResult(
        sigmas=sigmas,
        value=float(np.trace(problem.P)) + extra,
        extra=extra,
        weights=alpha,
        coefficients=C,
        gains=gains,
        step=None if power_mode == "per_step" else steps[0],
        power_mode=power_mode,
        budget=problem.power,
    )


def recursion_objective(
    system_or_scenario: str | Scenario | LinearSystem,
    sigmas: np.ndarray,
    weights: np.ndarray | None = None,
) -> float:
    """``Σ_m α_m tr M[K+m]`` by running the unaware filter's actual-covariance recursion.

    ``M[K−1] = P[K−1|K−1]`` (steady state, every sensor) and
    ``M[k] = (I − W H)(F M[k−1] F' + Q)(I − W H)' + W (R + Σ[k]) W'`` with the steady gain W.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        sigmas: (N, nz, nz) ``Σ[K..K+N−1]``.
        weights: (N,) time weights α (default equal).
    """
    system = resolve_system(system_or_scenario).system
    sigmas = as_float_array("sigmas", sigmas, f"an (N, {system.nz}, {system.nz}) array of numbers")
    if sigmas.ndim != 3 or sigmas.shape[1:] != (system.nz, system.nz):
        raise ValueError(
            f"sigmas must have shape (N, {system.nz}, {system.nz}), got {sigmas.shape}"
        )
    check_finite("sigmas", sigmas)
    for j, sigma in enumerate(sigmas):
        check_psd(f"sigmas[{j}]", sigma)
    alpha = check_weights(weights, sigmas.shape[0])
    _, P, W = steady_state(system)
    M, total = P, 0.0
    for a, sigma in zip(alpha, sigmas, strict=True):
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, W, sigma)
        total += a * float(np.trace(M))
    return total
