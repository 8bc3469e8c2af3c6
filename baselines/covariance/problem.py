"""The single-injection attack-covariance problem of docs/math.md §2.2–2.3 and its validated inputs.

The filter is in steady state with every sensor; at the attack time K it updates with the
nominal gain W while the measurements carry a zero-mean bias ``b ~ N(0, Σ)``, so its actual
error covariance is ``P[K|K] + W Σ W'`` (docs/math.md §2.1, single injection). The attacker's power
constraint is ``tr(Ω Σ) = a²``. Every solver works in the substituted variable

    Σ̃ = Ω^{1/2} Σ Ω^{1/2},   W̃ = W Ω^{-1/2},   so   W Σ W' = W̃ Σ̃ W̃',   tr(Ω Σ) = tr(Σ̃),

which turns the weighted power into a plain trace.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from baselines._inputs import resolve_system
from fdia_env._validation import as_matrix, check_positive, check_psd
from fdia_env.kalman import steady_state
from fdia_env.scenarios import Scenario, scenario_default
from fdia_env.systems import LinearSystem, check_system, power_weight


def weight_roots(weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Ω^{1/2}, Ω^{-1/2})`` of a symmetric positive definite (d, d) weight, both symmetric."""
    w, v = np.linalg.eigh(weight)
    half = (v * np.sqrt(w)) @ v.T
    inv_half = (v / np.sqrt(w)) @ v.T
    return 0.5 * (half + half.T), 0.5 * (inv_half + inv_half.T)


def check_weight(weight: Any, nz: int) -> np.ndarray:
    """Ω as a read-only (nz, nz) symmetric positive definite matrix, or ``ValueError``."""
    arr = as_matrix("weight", weight)
    if arr.shape != (nz, nz):
        raise ValueError(
            f"weight must be an (nz, nz) = ({nz}, {nz}) matrix matching the sensors' stacked "
            f"measurement, got shape {arr.shape}"
        )
    check_psd("weight", arr, strict=True)
    return arr


def resolve_power(scenario: Scenario, power: Any) -> float:
    """``power`` (a² > 0) if given, else the scenario's; ``ValueError`` naming ``power``."""
    return check_positive("power", scenario_default(scenario, "power", power))


@dataclass(frozen=True, eq=False)
class CovarianceProblem:
    """A validated single-injection instance.

    Attributes:
        system: The linear Gaussian system (stacked measurement size nz).
        power: Attack power a² > 0.
        weight: (nz, nz) power weighting Ω, symmetric positive definite.

    Derived (computed in ``__post_init__``):
        P: (n, n) steady-state filtered covariance ``P[K|K]`` with every sensor.
        W: (n, nz) steady-state gain.
        weight_half: (nz, nz) ``Ω^{1/2}``; weight_inv_half: (nz, nz) ``Ω^{-1/2}``.
        W_tilde: (n, nz) ``W Ω^{-1/2}``.
    """

    system: LinearSystem
    power: float
    weight: np.ndarray
    P: np.ndarray = field(init=False, repr=False)
    W: np.ndarray = field(init=False, repr=False)
    weight_half: np.ndarray = field(init=False, repr=False)
    weight_inv_half: np.ndarray = field(init=False, repr=False)
    W_tilde: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        check_system(self.system)
        power = check_positive("power", self.power)
        weight = check_weight(self.weight, self.system.nz)
        _, P, W = steady_state(self.system)
        half, inv_half = weight_roots(weight)
        W_tilde = W @ inv_half
        for name, value in (
            ("power", power),
            ("weight", weight),
            ("P", P),
            ("W", W),
            ("weight_half", half),
            ("weight_inv_half", inv_half),
            ("W_tilde", W_tilde),
        ):
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def from_tilde(self, sigma_tilde: np.ndarray) -> np.ndarray:
        """``Σ = Ω^{-1/2} Σ̃ Ω^{-1/2}``, symmetrised."""
        sigma = self.weight_inv_half @ sigma_tilde @ self.weight_inv_half
        return 0.5 * (sigma + sigma.T)


def make_problem(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    weight: np.ndarray | None = None,
) -> CovarianceProblem:
    """Build a :class:`CovarianceProblem`.

    The solvers of :mod:`baselines.covariance` take these arguments first and pass them here.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`; the filter
            is in steady state with every sensor.
        power: a² > 0 (default: the scenario's).
        weight: (nz, nz) power weighting Ω, symmetric positive definite (default
            :func:`~fdia_env.systems.power_weight`).

    Returns:
        The problem: the steady-state filter with every sensor, a² and Ω.

    Raises:
        ValueError: Naming the parameter: a power that is not a finite number > 0 (or missing
            where the scenario has none); a weight of the wrong shape, not symmetric or not
            positive definite; an unknown scenario.
    """
    sc = resolve_system(system_or_scenario)
    a2 = resolve_power(sc, power)
    omega = power_weight(sc.system) if weight is None else weight
    return CovarianceProblem(sc.system, a2, omega)
