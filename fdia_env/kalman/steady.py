"""Steady state of the Kalman filter for a fixed sensor subset (docs/math.md §1).

Checked, never silent: the subset must be detectable with F (PBH test, else ``ValueError``
naming the subset and the eigenvalue: a single-sensor subset of the sensor game can fail where
the whole system passes); a marginal mode of F without process noise has no steady state (its
covariance decays only like 1/k: ``ValueError``); the DARE solution is accepted only when its
relative residual is below ``1e-8``, and the fixed-point fallback raises ``RuntimeError`` with
the relative change reached when it does not converge in ``max_iter`` steps.
"""

from __future__ import annotations

import weakref

import numpy as np
import scipy.linalg

from fdia_env.kalman.filter import information_update, masked_gain, predict_cov
from fdia_env.kalman.linalg import spd_inv, sym
from fdia_env.systems import LinearSystem, check_detectable, noise_factor, pbh_defects
from fdia_env.systems.system import PBH_TOL


def _sensor_rows(system: LinearSystem, mask: np.ndarray | None) -> np.ndarray:
    if mask is None:
        return np.ones(system.nz, dtype=bool)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (system.M,):
        raise ValueError(f"mask must have shape ({system.M},), got {mask.shape}")
    if not mask.any():
        raise ValueError("mask must select at least one sensor for a steady state to exist")
    return system.row_mask(mask)


# system -> {used-sensor key: (P_pred, P_post, W)}; systems are immutable, so results are too
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def steady_state(
    system: LinearSystem, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steady-state ``(P[k+1|k], P[k|k], W)`` from the discrete algebraic Riccati equation.

    ``scipy.linalg.solve_discrete_are(F', H', Q, R)`` gives the predicted covariance; one
    update gives the filtered one. Falls back to :func:`steady_state_iterate` when the DARE
    solver fails (e.g. Q = 0, where the filtered covariance tends to zero). Results are cached
    per (system, subset) and returned as read-only arrays: a :class:`LinearSystem` is immutable.

    Args:
        system: The system.
        mask: (M,) sensors used (default all).

    Returns:
        Predicted covariance (n, n), filtered covariance (n, n), gain (n, nz) with zero columns
        for unused sensors.
    """
    rows = _sensor_rows(system, mask)
    key = rows.tobytes()
    cached = _CACHE.setdefault(system, {})
    if key not in cached:
        _check_steady_state_exists(system, mask, rows)
        result = _solve_dare(system, mask, rows)
        for a in result:
            a.setflags(write=False)
        cached[key] = result
    return cached[key]


def _subset_name(system: LinearSystem, mask: np.ndarray | None) -> str:
    if mask is None:
        return f"all sensors of system {system.name!r}"
    used = [s.name or f"#{i}" for i, s in enumerate(system.sensors) if mask[i]]
    return f"sensor subset {used} (mask {np.asarray(mask, dtype=int).tolist()}) of {system.name!r}"


def _check_steady_state_exists(
    system: LinearSystem, mask: np.ndarray | None, rows: np.ndarray
) -> None:
    what = _subset_name(system, None if mask is None else np.asarray(mask, dtype=bool))
    check_detectable(system.F, system.H[rows], what)
    bad = pbh_defects(system.F, noise_factor(system.Q), side="cols", unstable_only=False)
    quiet = _stable_modes_without_noise(system)
    if quiet and not bad:
        raise ValueError(
            f"no steady state for {what}: Q gives no process noise to the stable mode of F with "
            f"eigenvalue {quiet[0]:.6g}, so its error covariance decays to 0 and the steady "
            "state is singular (the information form cannot represent it); give Q a component "
            "along that mode, or use a finite warmup instead of 'steady'"
        )
    if bad:
        raise ValueError(
            f"no steady state for {what}: the marginal mode of F with eigenvalue {bad[0]:.6g} "
            "receives no process noise, so its error covariance decays to 0 only like 1/k "
            "(e.g. a static parameter, F = I, Q = 0); use a finite warmup instead of 'steady'"
        )


def _tracking_closed_form(
    system: LinearSystem, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Steady state of the white-noise-acceleration model with position sensors, in closed form.

    ``F = [[1, T], [0, 1]]``, ``Q = σ_v² Γ Γ'`` with ``Γ = [T²/2, T]'`` and used measurement rows
    ``[1, 0]`` (noise variances ``σ_i²``, fused into ``σ² = (Σ σ_i⁻²)⁻¹``): the steady state is
    the α-β filter of the tracking index ``λ = σ_v T²/σ`` (Kalata; docs/math.md §1),

        u = 1 − r = 2λ / (λ + √(λ² + 8λ)),   r = 8λ / (λ + √(λ² + 8λ))²,
        α = u (2 − u),   β = 2u²,
        P[k|k] = σ² [[α, β/T], [β/T, 4u³/(r T²)]],

    written without the cancellations of the textbook form (``1 − r`` at λ = 1e-150, ``r`` at
    λ = 1e150), so it holds at any index where the Riccati solvers and the iteration fail.

    Returns:
        ``(P[k+1|k], P[k|k])``, or None when the system is not of this form.
    """
    F, Q = np.asarray(system.F, dtype=float), np.asarray(system.Q, dtype=float)
    if F.shape != (2, 2) or not (F[0, 0] == 1.0 and F[1, 1] == 1.0 and F[1, 0] == 0.0):
        return None
    T = float(F[0, 1])
    if not T > 0.0:
        return None
    gamma = np.array([T * T / 2.0, T])
    q = Q[1, 1] / (T * T)
    if not (np.isfinite(q) and q > 0.0) or not np.allclose(
        Q, q * np.outer(gamma, gamma), rtol=1e-12, atol=0.0
    ):
        return None
    H = np.asarray(system.H, dtype=float)[rows]
    R = np.asarray(system.R, dtype=float)[np.ix_(rows, rows)]
    if not (np.all(H[:, 0] == 1.0) and np.all(H[:, 1] == 0.0)):
        return None
    if np.any(R - np.diag(np.diag(R))):  # correlated position noises: not the fused form
        return None
    sigma2 = 1.0 / np.sum(1.0 / np.diag(R))
    lam = np.sqrt(q) * (T * T) / np.sqrt(sigma2)
    root = np.sqrt(lam) * np.sqrt(lam + 8.0)  # √(λ² + 8λ) without overflow
    u = 2.0 * lam / (lam + root)
    r = 8.0 * lam / (lam + root) ** 2
    alpha, beta = u * (2.0 - u), 2.0 * u * u
    P_post = sigma2 * np.array(
        [[alpha, beta / T], [beta / T, 4.0 * u**3 / (r * T * T)]], dtype=float
    )
    if not np.all(np.isfinite(P_post)):
        return None
    P_pred = sym(F @ P_post @ F.T + Q)
    return P_pred, P_post


def _information(system: LinearSystem, mask: np.ndarray | None) -> np.ndarray:
    """``Σ_used J_i`` (n, n)."""
    if mask is None:
        return system.J.sum(axis=0)
    return np.einsum("m,mij->ij", np.asarray(mask, dtype=float), system.J)


def _random_walk_doubling(
    system: LinearSystem, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Steady state of a random walk (``F = I``) by the doubling algorithm, verified.

    With ``Q`` far below the sensors' noise (a grid with ``q = 1e-300``) the closed loop is
    within ``√(q/σ²)`` of the unit circle: the iteration never converges and the Schur solver
    sees a marginal pencil. The structure-preserving doubling algorithm (``A₀ = I``,
    ``G₀ = Σ J_i``, ``H₀ = Q``; ``W = I + G H``, ``A ← A W⁻¹ A``, ``G ← G + A W⁻¹ G A'``,
    ``H ← H + A' H W⁻¹ A``) runs the Riccati recursion ``2^k`` steps at a time. The answer is
    accepted only if ``P[k|k] J P[k|k−1] = Q`` to 1e-6: for ``F = I`` that product equals
    ``P[k|k−1] − P[k|k]``, the DARE's own residual, without the cancellation of forming the
    difference of two covariances 1e146 times larger than Q.

    Returns:
        ``(P[k+1|k], P[k|k])``, or None when ``F`` is not the identity or the check fails.
    """
    n = system.n
    if not np.array_equal(system.F, np.eye(n)):
        return None
    J = _information(system, mask)
    Q = np.asarray(system.Q, dtype=float)
    q, g = np.abs(Q).max(), np.abs(J).max()
    if not (q > 0.0 and g > 0.0):
        return None
    c = np.sqrt(q) / np.sqrt(g)  # P = c P̃ with Q̃ = Q / c and G̃ = c J of one size
    A, G, Hk = np.eye(n), c * J, Q / c
    for _ in range(3000):
        W = np.eye(n) + G @ Hk
        WA, WG = np.linalg.solve(W, A), np.linalg.solve(W, G)
        H_new = sym(Hk + A.T @ Hk @ WA)
        G, A = sym(G + A @ WG @ A.T), A @ WA
        if not np.all(np.isfinite(H_new)):
            return None
        change = np.abs(H_new - Hk).max() / max(np.abs(H_new).max(), 1e-300)
        Hk = H_new
        if change <= 1e-15:
            break
    else:
        return None
    P_pred = c * Hk
    try:
        P_post = spd_inv(spd_inv(P_pred) + J)
    except np.linalg.LinAlgError:
        return None
    residual = np.abs(P_post @ J @ P_pred - Q).max() / q
    if not (np.isfinite(residual) and residual <= 1e-6):
        return None
    return P_pred, sym(P_post)


def _out_of_reach(system: LinearSystem, mask: np.ndarray | None, exc: RuntimeError) -> str:
    """Why a detectable subset has no computable steady state (the scales are too far apart)."""
    what = _subset_name(system, None if mask is None else np.asarray(mask, dtype=bool))
    q = float(np.linalg.eigvalsh(system.Q).max())
    used = system.J if mask is None else system.J[np.asarray(mask, dtype=bool)]
    j = float(np.linalg.eigvalsh(used.sum(axis=0)).max())
    return (
        f"no steady state computable in float64 for {what}: its unstable modes are detectable, "
        f"but the process noise and the sensors' information are too far apart in scale "
        f"(√(λ_max(Q) λ_max(Σ J)) = {np.sqrt(q) * np.sqrt(j):.3g}; for tracking_system this is "
        "the tracking index σ_v T²/σ_w, and about 1e-8 to 1e6 is solvable): the Riccati "
        f"recursion cannot resolve it ({str(exc).split(' (is every')[0]})"
    )


def _stable_modes_without_noise(system: LinearSystem) -> list[complex]:
    """Eigenvalues ``|μ| < 1`` of F where ``rank [F − μI, Q^{1/2}] < n`` (no noise reaches)."""
    F = np.asarray(system.F, dtype=float)
    n = F.shape[0]
    B = noise_factor(system.Q)
    b_max = float(np.abs(B).max()) if B.size else 0.0
    B = B / b_max if b_max > 0.0 else B
    f_scale = max(1.0, float(np.abs(F).max()))
    quiet = []
    for mu in np.linalg.eigvals(F):
        if abs(mu) >= 1.0 - PBH_TOL:
            continue  # marginal and unstable modes: pbh_defects
        M = np.hstack([(F - mu * np.eye(n)) / f_scale, B])
        if np.linalg.svd(M, compute_uv=False)[n - 1] <= PBH_TOL:
            quiet.append(complex(mu))
    return quiet


def _dare_residual(system: LinearSystem, P_pred: np.ndarray, rows: np.ndarray) -> float:
    """Relative residual of ``P = F (P − P H' (H P H' + R)⁻¹ H P) F' + Q`` on the used rows."""
    H, R = system.H[rows], system.R[np.ix_(rows, rows)]
    S = H @ P_pred @ H.T + R
    post = P_pred - P_pred @ H.T @ np.linalg.solve(S, H @ P_pred)
    res = system.F @ post @ system.F.T + system.Q - P_pred
    return float(np.abs(res).max() / max(np.abs(P_pred).max(), 1e-300))


def _solve_dare(
    system: LinearSystem, mask: np.ndarray | None, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    H, R = system.H[rows], system.R[np.ix_(rows, rows)]
    # P(cQ, cR) = c P(Q, R): solved at unit noise scale, so that covariances of 1e-300 (or
    # 1e300) are neither lost to underflow nor rejected by the solver's absolute tolerances
    c = float(np.abs(R).max())
    try:
        P_pred = c * sym(scipy.linalg.solve_discrete_are(system.F.T, H.T, system.Q / c, R / c))
        if not np.all(np.isfinite(P_pred)) or np.linalg.eigvalsh(P_pred).min() <= 0:
            raise np.linalg.LinAlgError("non-positive DARE solution")
        if _dare_residual(system, P_pred, rows) > 1e-8:
            raise np.linalg.LinAlgError("inaccurate DARE solution")
    except (np.linalg.LinAlgError, ValueError):
        closed = _tracking_closed_form(system, rows) or _random_walk_doubling(system, mask)
        if closed is not None:  # an extreme index: closed form, or doubling where F = I
            P_pred, P_post = closed
            return P_pred, P_post, masked_gain(P_post, system, mask)
        try:
            return steady_state_iterate(system, mask)
        except RuntimeError as exc:
            raise RuntimeError(_out_of_reach(system, mask, exc)) from exc
    P_post = information_update(P_pred, system.J, mask)
    return P_pred, P_post, masked_gain(P_post, system, mask)


def steady_state_iterate(
    system: LinearSystem,
    mask: np.ndarray | None = None,
    *,
    P0: np.ndarray | None = None,
    tol: float = 1e-13,
    max_iter: int = 100_000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed point of the covariance recursion, batched over (..., M) masks.

    Iterates ``P[k|k] = ((F P F' + Q)⁻¹ + Σ_used J_i)⁻¹`` until the relative change is below
    ``tol`` in every batch member.

    Returns:
        Predicted (..., n, n), filtered (..., n, n) covariances and the gain (..., n, nz).

    Raises:
        RuntimeError: If some member has not converged after ``max_iter`` iterations (the
            message gives the relative change reached), or the iterate is no longer finite.
    """
    mask_arr = None if mask is None else np.asarray(mask, dtype=bool)
    batch = () if mask_arr is None else mask_arr.shape[:-1]
    P = np.broadcast_to(system.P0 if P0 is None else P0, (*batch, system.n, system.n)).copy()
    change = np.inf
    for _ in range(max_iter):
        P_pred = predict_cov(P, system.F, system.Q)
        P_new = information_update(P_pred, system.J, mask_arr)
        scale = np.maximum(np.abs(P_new).max(axis=(-2, -1)), 1e-300)
        change = np.abs(P_new - P).max(axis=(-2, -1)) / scale
        P = P_new
        if not np.all(np.isfinite(P)):
            raise RuntimeError(
                f"steady_state_iterate diverged for system {system.name!r}: the covariance is "
                "no longer finite (is every unstable mode detectable by the used sensors?)"
            )
        if np.all(change <= tol):
            break
    else:
        raise RuntimeError(
            f"steady_state_iterate did not converge for system {system.name!r} in {max_iter} "
            f"iterations: relative change {float(np.max(change)):.3g} > tol {tol:g}"
        )
    P_pred = predict_cov(P, system.F, system.Q)
    return P_pred, P, masked_gain(P, system, mask_arr)
