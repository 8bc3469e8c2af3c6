"""Trace-optimal bias covariance for a single injection (docs/math.md §2.2), and its special cases.

Maximise ``tr(P + W Σ W')`` over ``Σ ⪰ 0`` with ``tr(Ω Σ) = a²``. With ``Σ̃ = Ω^{1/2} Σ Ω^{1/2}``
and ``W̃ = W Ω^{-1/2}`` the objective is ``tr P + tr(Σ̃ W̃' W̃)``, linear in ``Σ̃`` over the set
``{Σ̃ ⪰ 0, tr Σ̃ = a²}`` whose extreme points are ``a² u u'`` with ``|u| = 1``; so

    max = tr P + a² λ_max(W̃' W̃),   Σ* = a² Ω^{-1/2} u u' Ω^{-1/2},  u the top eigenvector.

Dependent biases (``structure="full"``) are therefore fully correlated. Independent biases
across sensors (``structure="diagonal"``, Σ block diagonal, one block per sensor) split the
problem into one such problem per sensor that share the power; the objective is linear in the
blocks' powers, so all the power goes to the sensor with the largest
``λ_max(Ω_ii^{-1/2} W_i' W_i Ω_ii^{-1/2})`` (for a position sensor, ``‖W_i‖²``: its gain
column's squared norm), as a rank-one block.

The literature's special cases are separate functions so the tests can check that each is the
general rule: :func:`independent_position_rule`, :func:`dependent_position_rule` and
:func:`pv_single_sensor_rule`.
"""

from __future__ import annotations

import numpy as np

from baselines._inputs import resolve_system
from baselines.covariance.problem import CovarianceProblem, make_problem, weight_roots
from baselines.covariance.result import CovarianceResult
from fdia_env._validation import check_choice
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

STRUCTURES = ("full", "diagonal")


def top_eigenvector(A: np.ndarray) -> tuple[float, np.ndarray]:
    """Largest eigenvalue of symmetric ``A`` and a unit eigenvector, sign fixed.

    The sign makes the entry of largest magnitude positive, so a rank-one ``u u'`` is the same
    whichever way LAPACK returns the vector and correlations come out positive where they can.
    """
    w, V = np.linalg.eigh(0.5 * (A + A.T))
    u = V[:, -1]
    return float(w[-1]), u * np.sign(u[np.argmax(np.abs(u))])


def trace_optimal(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    structure: str = "full",
    weight: np.ndarray | None = None,
) -> CovarianceResult:
    """The bias covariance that maximises ``tr(P[K|K] + W Σ W')`` under ``tr(Ω Σ) = a²``.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`; the filter
            is in steady state with every sensor.
        power: a² > 0 (default: the scenario's).
        structure: ``"full"`` (dependent biases: rank one along the top eigenvector of
            ``W̃' W̃``) or ``"diagonal"`` (independent across sensors: a rank-one block on the
            best sensor, zero elsewhere).
        weight: (nz, nz) power weighting Ω, symmetric positive definite (default
            :func:`~fdia_env.systems.power_weight`). With ``"diagonal"`` only Ω's diagonal
            blocks enter ``tr(Ω Σ)``, since Σ is block diagonal.

    Returns:
        ``value = tr(P + W Σ W')``. ``info["gain"]`` is the attained ``λ_max``
        (so ``value = tr P + a² · gain``); for ``"diagonal"``, ``info["sensor"]`` is the
        attacked sensor (0-based) and ``info["sensor_gains"]`` every sensor's ``λ_max``.

    Raises:
        ValueError: Naming the parameter, for an unknown structure, a power that is not a finite
            number > 0, or a bad weight.

    Example:
        >>> round(trace_optimal("ch2-position").value, 1)
        609.9
        >>> round(trace_optimal("ch2-position", structure="diagonal").value, 1)
        390.8
    """
    check_choice("structure", structure, STRUCTURES)
    problem = make_problem(system_or_scenario, power, weight)
    if structure == "full":
        return _full(problem)
    return _diagonal(problem)


def _full(problem: CovarianceProblem) -> CovarianceResult:
    Wt = problem.W_tilde
    gain, u = top_eigenvector(Wt.T @ Wt)  # λ_max(W̃' W̃), Σ̃* = a² u u'
    sigma = problem.from_tilde(problem.power * np.outer(u, u))
    return CovarianceResult.of(problem, sigma, "trace", "eigenvector", gain=gain)


def _diagonal(problem: CovarianceProblem) -> CovarianceResult:
    system = problem.system
    gains, vectors = [], []
    for i in range(system.M):
        rows = system.sensor_slice(i)
        _, inv_half = weight_roots(problem.weight[rows, rows])  # Ω_ii^{-1/2}
        Wi = problem.W[:, rows] @ inv_half
        gain, u = top_eigenvector(Wi.T @ Wi)
        gains.append(gain)
        vectors.append(inv_half @ u)  # Σ_i = a² (Ω_ii^{-1/2} u)(Ω_ii^{-1/2} u)'
    best = int(np.argmax(gains))
    sigma = np.zeros((system.nz, system.nz))
    rows = system.sensor_slice(best)
    sigma[rows, rows] = problem.power * np.outer(vectors[best], vectors[best])
    return CovarianceResult.of(
        problem,
        sigma,
        "trace",
        "best-sensor eigenvector",
        gain=gains[best],
        sensor=best,
        sensor_gains=np.array(gains),
    )


# --- special cases the literature states separately ---------------------------------------


def _position_noise(system: LinearSystem, rule: str) -> np.ndarray:
    """(M,) noise variances of sensors that all measure the same scalar, else ``ValueError``."""
    H0 = system.sensors[0].H
    for i, s in enumerate(system.sensors):
        if s.dim != 1 or not np.array_equal(s.H, H0):
            raise ValueError(
                f"system_or_scenario: {rule} needs scalar sensors with one common H (e.g. "
                "position sensors); "
                f"sensor {i} has H = {s.H.tolist()}, sensor 0 has H = {H0.tolist()}"
            )
    return np.array([s.R[0, 0] for s in system.sensors])


def independent_position_rule(
    system_or_scenario: str | Scenario | LinearSystem, power: float | None = None
) -> CovarianceResult:
    """Independent biases, M position sensors: all power on the sensor with the smallest σ_w.

    The gain columns are ``W_i = P[K|K] H' / σ_{w,i}²``, so the largest gain column norm belongs
    to the smallest σ_w (docs/math.md §2.2).

    Raises:
        ValueError: If the sensors are not scalar sensors with one common H, or for a bad power.

    Example:
        >>> result = independent_position_rule("ch2-position")
        >>> result.variances.tolist(), round(result.value, 1)
        ([3000.0, 0.0], 390.8)
    """
    sc = resolve_system(system_or_scenario)
    r = _position_noise(sc.system, "independent_position_rule")
    problem = make_problem(sc, power)
    best = int(np.argmin(r))
    sigma = np.zeros((sc.system.nz, sc.system.nz))
    sigma[best, best] = problem.power
    return CovarianceResult.of(problem, sigma, "trace", "independent position rule", sensor=best)


def dependent_position_rule(
    system_or_scenario: str | Scenario | LinearSystem, power: float | None = None
) -> CovarianceResult:
    """Dependent biases, M position sensors: correlation 1, ``σ_{b,i} = c_i a / ‖c‖``.

    ``c_i = (1/σ_{w,i}²) / Σ_j (1/σ_{w,j}²)``: the gain columns are proportional to
    ``1/σ_{w,i}²``, so this is the top eigenvector of ``W' W`` (docs/math.md §2.2).

    Raises:
        ValueError: If the sensors are not scalar sensors with one common H, or for a bad power.

    Example:
        >>> result = dependent_position_rule("ch2-position")
        >>> result.variances.round(6).tolist(), round(result.value, 1)
        ([1920.0, 1080.0], 609.9)
    """
    sc = resolve_system(system_or_scenario)
    r = _position_noise(sc.system, "dependent_position_rule")
    problem = make_problem(sc, power)
    c = (1.0 / r) / np.sum(1.0 / r)
    std = c * np.sqrt(problem.power) / np.linalg.norm(c)  # σ_{b,i}
    return CovarianceResult.of(problem, np.outer(std, std), "trace", "dependent position rule", c=c)


def pv_single_sensor_rule(
    system_or_scenario: str | Scenario | LinearSystem, power: float | None = None
) -> CovarianceResult:
    """One position+velocity sensor: the literature's closed form (docs/math.md §2.2).

    With the steady-state gain ``W = [[w11, w12], [w21, w22]]`` and power ``σ_bp² + T² σ_bv² = a²``:

        ρ = sign(w11 w12 + w21 w22),  σ_bp = a sin θ*,  σ_bv = (a/T) cos θ*,  θ* = π/4 − φ/2,
        φ = arctan[(β2 − β1 T²) / (2T (α1 + α2))],  β1 = w11² + w21²,  β2 = w12² + w22²,

    with ``α1 + α2 = |w11 w12 + w21 w22|``. Derivation: with ``σ_bp = a sin θ``,
    ``σ_bv = (a/T) cos θ`` and ``|ρ| = 1`` the extra trace is
    ``a² [β1 sin²θ + (β2/T²) cos²θ + (2/T)(α1 + α2) sin θ cos θ]``, a sinusoid in 2θ whose
    maximum is at ``2θ = π/2 − φ``. ``arctan2`` is used so ``α1 + α2 = 0`` (then ``φ = ±π/2``:
    all power on one component) needs no special case; ρ is then taken as +1.

    Raises:
        ValueError: Unless the system has exactly one sensor with ``H = I₂``, or for a bad power.

    Example:
        >>> result = pv_single_sensor_rule("ch2-pv-1")
        >>> round(result.info["rho"]), round(result.value, 2)
        (1, 805.55)
    """
    sc = resolve_system(system_or_scenario)
    system = sc.system
    if system.M != 1 or not np.array_equal(system.sensors[0].H, np.eye(2)):
        raise ValueError(
            "system_or_scenario: pv_single_sensor_rule needs exactly one position+velocity sensor "
            "(H = I₂), got "
            f"{system.M} sensor(s) with H = {[s.H.tolist() for s in system.sensors]}"
        )
    problem = make_problem(sc, power)
    (w11, w12), (w21, w22) = problem.W
    T, a = system.T, np.sqrt(problem.power)
    beta1, beta2 = w11**2 + w21**2, w12**2 + w22**2
    cross = w11 * w12 + w21 * w22
    rho = 1.0 if cross >= 0.0 else -1.0
    phi = np.arctan2(beta2 - beta1 * T**2, 2.0 * T * abs(cross))  # α1 + α2 = |cross|
    theta = np.pi / 4.0 - phi / 2.0
    sp, sv = a * np.sin(theta), (a / T) * np.cos(theta)  # σ_bp, σ_bv
    sigma = np.array([[sp**2, rho * sp * sv], [rho * sp * sv, sv**2]])
    return CovarianceResult.of(
        problem, sigma, "trace", "single pv sensor rule", rho=rho, theta=theta, phi=phi
    )
