"""Stealthy attacks on a Kalman filter with a χ² innovation detector (Mo & Sinopoli 2010).

System ``x[k+1] = A x[k] + w``, ``y = C x + v`` (``w ~ N(0, Q)``, ``v ~ N(0, R)``), the
steady-state Kalman filter ``x̂[k+1] = A x̂[k] + K (y[k+1] − C A x̂[k])`` with the χ² detector on
its innovation ``z[k+1] = y[k+1] − C A x̂[k]`` (covariance ``C P C' + R``, P the predicted
steady state). The attacker adds ``Γ a[k]`` to the readings of the sensors S (Γ: the columns
of I for S). By linearity the attack changes the estimation error and the innovation by

    Δe[k+1] = (A − K C A) Δe[k] − K Γ a[k+1],     Δz[k+1] = C A Δe[k] + Γ a[k+1]

(Δe is the change of the error ``x − x̂``). The attack is *stealthy* when Δz stays bounded
(the detector's statistic then keeps its distribution up to a bounded shift) and *succeeds*
when Δe is unbounded. Mo & Sinopoli's condition: a successful stealthy attack on S exists iff
A has an eigenvector v of an eigenvalue ``|λ| ≥ 1`` with ``C v`` supported on S
(``C v ∈ span Γ``) that is reachable for ``(A − KCA, −KΓ)``. :func:`mo_sinopoli` tests it
and builds the attack:

- a *reach* phase of n steps: the least-norm inputs that take Δe from 0 to v;
- then a *hand-over*: once Δe contains ``s v``, the input ``−s λ (C v)_S`` cancels that part's
  innovation exactly (``C v`` lives on S), so it grows as ``s λ^k v`` at zero cost, while
  the reach phase repeats (adding v every n steps). The innovation change is the reach phase's,
  periodic and bounded; the error grows linearly (``|λ| = 1``) or geometrically (``|λ| > 1``).

The attack is built for a real eigenvalue; a set whose only admissible modes are complex is
reported vulnerable (``vulnerable``) with ``attack`` left ``None``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg

from fdia_env._validation import as_matrix, check_int, check_psd


@dataclass(frozen=True, eq=False)
class KalmanModel:
    """``(A, C, Q, R)`` with the steady-state gain K, predicted P and innovation covariance."""

    A: np.ndarray
    C: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    K: np.ndarray
    Pz: np.ndarray

    @property
    def n(self) -> int:
        """States."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Scalar measurements."""
        return self.C.shape[0]


def kalman_model(A: Any, C: Any, Q: Any, R: Any) -> KalmanModel:
    """Validate ``(A, C, Q, R)`` and compute the steady-state filter (scipy's DARE).

    Raises:
        ValueError: Naming the parameter for bad shapes, non-finite entries, Q not PSD or R
            not positive definite, or a pair (A, C) with no stabilising steady state.
    """
    A = as_matrix("A", A)
    n = A.shape[0]
    A = as_matrix("A", A, shape=(n, n))
    C = as_matrix("C", C, shape=(None, n))
    m = C.shape[0]
    Q = as_matrix("Q", Q, shape=(n, n))
    R = as_matrix("R", R, shape=(m, m))
    check_psd("Q", Q)
    check_psd("R", R, strict=True)
    try:
        P = linalg.solve_discrete_are(A.T, C.T, Q, R)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ValueError(
            f"(A, C, Q) has no stabilising steady-state Kalman filter: {exc} (is (A, C) "
            "detectable?)"
        ) from exc
    P = (P + P.T) / 2.0
    Pz = C @ P @ C.T + R
    K = np.linalg.solve(Pz, C @ P).T
    return KalmanModel(A=A, C=C, Q=Q, R=R, P=P, K=K, Pz=Pz)


@dataclass(frozen=True, eq=False)
class StealthyKalmanAttack:
    """Result of :func:`mo_sinopoli`.

    Attributes:
        vulnerable: Whether a stealthy attack on ``sensors`` can drive the error unbounded.
        sensors: The attacked sensors (positions of rows of C).
        eigenvalue: The unstable eigenvalue used (``None`` if not vulnerable).
        direction: v, the error direction that grows (unit norm; ``None`` if not vulnerable).
        reach: ``(n, |S|)``: the reach phase's inputs (``None`` if not vulnerable or complex λ).
    """

    vulnerable: bool
    sensors: tuple[int, ...]
    model: KalmanModel
    eigenvalue: complex | None = None
    direction: np.ndarray | None = None
    reach: np.ndarray | None = None

    def attack(self, steps: int, scale: float = 1.0) -> np.ndarray:
        """(steps, m) the injections ``Γ a[k]`` for k = 1..steps (zeros off the sensors).

        Raises:
            ValueError: If the set is not vulnerable or the mode is complex (no attack built).
        """
        steps = check_int("steps", steps, minimum=1)
        if self.reach is None:
            raise ValueError(
                "no attack to play: the sensor set admits no unbounded stealthy attack"
                if not self.vulnerable
                else "the admissible unstable modes are complex: no real attack is built"
            )
        mdl, S = self.model, list(self.sensors)
        lam = float(np.real(self.eigenvalue))
        n = mdl.n
        Cv_S = (mdl.C @ self.direction)[S]
        out = np.zeros((steps, mdl.m))
        s = 0.0  # multiple of v handed over to the zero-innovation regime
        for k in range(steps):
            phase = k % n
            if phase == 0 and k > 0:
                s += 1.0  # the last reach phase ended at Δe = v (on top of s v)
            a = self.reach[phase] - s * lam * Cv_S
            out[k, S] = scale * a
            s *= lam
        return out

    def simulate(self, steps: int, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """``(Δe, Δz)``: (steps, n) error and (steps, m) innovation changes of the attack."""
        inj = self.attack(steps, scale)
        return attack_effect(self.model, inj)


def attack_effect(model: KalmanModel, injections: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Δe, Δz)`` of a sequence of (steps, m) injections on the steady-state filter."""
    A, C, K = model.A, model.C, model.K
    Abar = A - K @ C @ A
    de = np.zeros(model.n)
    E, Z = [], []
    for inj in np.asarray(injections, dtype=np.float64):
        dz = C @ A @ de + inj
        de = Abar @ de - K @ inj
        E.append(de.copy())
        Z.append(dz)
    return np.array(E), np.array(Z)


def _orth(M: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    if M.size == 0:
        return M.reshape(M.shape[0], 0)
    u, s, _ = np.linalg.svd(M, full_matrices=False)
    return u[:, s > tol * max(1.0, s[0] if s.size else 0.0)]


def _null(M: np.ndarray, n: int, tol: float = 1e-9) -> np.ndarray:
    if M.shape[0] == 0:
        return np.eye(n, dtype=M.dtype)
    _, s, vh = np.linalg.svd(M, full_matrices=True)
    rank = int(np.sum(s > tol * max(1.0, s[0] if s.size else 0.0)))
    return vh[rank:].conj().T


def _intersect(U: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Orthonormal basis of span U ∩ span V (both orthonormal columns)."""
    if U.shape[1] == 0 or V.shape[1] == 0:
        return U[:, :0]
    N = _null(np.hstack([U, -V]), U.shape[1] + V.shape[1])
    return _orth(U @ N[: U.shape[1]])


def mo_sinopoli(
    A: Any, C: Any, Q: Any, R: Any, sensors: Any, *, unstable_tol: float = 1e-9
) -> StealthyKalmanAttack:
    """Mo & Sinopoli's test: can a stealthy attack on ``sensors`` make the error unbounded?

    Args:
        A: (n, n) dynamics.
        C: (m, n) measurement matrix (one row per scalar sensor).
        Q: (n, n) process noise covariance (PSD).
        R: (m, m) measurement noise covariance (positive definite).
        sensors: Positions of the attacked rows of C.
        unstable_tol: ``|λ| ≥ 1 − unstable_tol`` counts as unstable.

    Returns:
        The :class:`StealthyKalmanAttack` (with the attack when one exists for a real mode).

    Raises:
        ValueError: Naming the parameter: a bad system (see :func:`kalman_model`), sensors
            outside 0..m−1 or repeated.

    Example:
        >>> F = [[1.0, 1.0], [0.0, 1.0]]  # position-velocity tracking, T = 1
        >>> C, Q, R = np.eye(2), 0.01 * np.eye(2), np.eye(2)
        >>> mo_sinopoli(F, C, Q, R, [0]).vulnerable, mo_sinopoli(F, C, Q, R, [1]).vulnerable
        (True, False)
    """
    model = kalman_model(A, C, Q, R)
    S = _sensors(sensors, model.m)
    n = model.n
    Gamma = np.eye(model.m)[:, S]
    Abar = model.A - model.K @ model.C @ model.A
    B = -model.K @ Gamma
    blocks, M = [], B
    for _ in range(n):
        blocks.append(M)
        M = Abar @ M
    reachable = _orth(np.hstack(blocks)) if S else np.zeros((n, 0))
    others = [i for i in range(model.m) if i not in set(S)]
    eig = np.linalg.eigvals(model.A)
    best = None
    for lam in _distinct(eig[np.abs(eig) >= 1.0 - unstable_tol]):
        E = _null(model.A - lam * np.eye(n), n, tol=1e-8)  # the eigenspace
        on_S = E @ _null(model.C[others] @ E, E.shape[1]) if others else E
        cand = _intersect(_orth(on_S), reachable.astype(on_S.dtype))
        if cand.shape[1]:
            real = abs(lam.imag) <= 1e-12
            if best is None or (real and not best[2]):
                best = (lam, cand[:, 0], real)
    if best is None:
        return StealthyKalmanAttack(False, tuple(S), model)
    lam, v, real = best
    if not real:
        return StealthyKalmanAttack(True, tuple(S), model, complex(lam), v)
    v = np.real(v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))])))
    v = v / np.linalg.norm(v)
    # least-norm inputs a[1..n] with Σ_j Abar^{n−j} B a[j] = v
    W = np.hstack([np.linalg.matrix_power(Abar, n - 1 - j) @ B for j in range(n)])
    u = np.linalg.lstsq(W, v, rcond=None)[0]
    reach = u.reshape(n, len(S))
    return StealthyKalmanAttack(True, tuple(S), model, complex(lam), v, reach)


def _sensors(sensors: Any, m: int) -> list[int]:
    try:
        items = [int(s) if not isinstance(s, bool) else None for s in np.atleast_1d(sensors)]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"sensors must be positions 0..{m - 1}, got {sensors!r}") from exc
    if any(s is None or not 0 <= s < m for s in items) or len(set(items)) != len(items):
        raise ValueError(f"sensors must be distinct positions 0..{m - 1}, got {sensors!r}")
    return sorted(items)


def _distinct(values: np.ndarray, tol: float = 1e-7) -> list[complex]:
    out: list[complex] = []
    for v in values:
        if all(abs(v - w) > tol for w in out):
            out.append(complex(v))
    return out
