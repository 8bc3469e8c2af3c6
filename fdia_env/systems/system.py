"""Linear Gaussian systems and their sensors (docs/math.md §1).

Validation when a system is built (every preset passes):

- numeric, finite, correctly shaped matrices; ``F`` non-empty and square; ``T > 0``; ``name`` a
  string; ``sensors`` a non-empty sequence of :class:`Sensor`;
- **scale**: the entries of ``Q``, ``R``, ``P0`` and of the informations ``H_i' R_i⁻¹ H_i`` and
  ``P0⁻¹`` at most :data:`~fdia_env._validation.MAX_COVARIANCE` (1e304) in magnitude. Inside it
  every env is exact at any scale (Q, R and P0 scaled by s give s times the covariances, down to
  about 1e-303 and up to 1e304); beyond it a trace or a sampled squared error overflows float64,
  or an information's inverse underflows. ``Q`` has no lower limit (a process noise of 1e-300
  next to a measurement noise of 1 is the tracking model at σ_v = 1e-150);
- **detectability** of ``(F, H)`` with all sensors: the PBH test ``rank [F − μI; H] = n`` at
  every eigenvalue with ``|μ| >= 1 − 1e-9`` (unstable or marginal), rank decided by the smallest
  singular value against ``1e-9 · max(1, |F|, |H|)``: a mode that grows (or persists) unseen
  makes the filter's covariance diverge (NaN observations, rewards) and the steady state
  meaningless. The tracking model's double eigenvalue 1 is detectable with a position sensor;
- **stabilisability** of ``(F, Q^{1/2})`` at every *strictly unstable* eigenvalue
  (``|μ| > 1 + 1e-9``): such a mode must be driven by process noise for the Riccati equation to
  have its stabilising solution. Marginal noise-free modes are allowed (a static parameter,
  ``F = I``, ``Q = 0``: ch3-static); their covariance tends to 0 only like 1/k, so they have no
  steady state (:func:`~fdia_env.kalman.steady_state` says so).

Subsets of sensors are checked when a steady state is requested for them
(:func:`~fdia_env.kalman.steady_state`). Arrays are read-only, also after ``pickle`` or
``copy.deepcopy`` (the steady-state cache relies on it).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import block_diag

from fdia_env._validation import (
    as_matrix,
    as_vector,
    check_magnitude,
    check_positive,
    check_psd,
)

PBH_TOL = 1e-9  # relative tolerance of the PBH rank tests and of "marginal" (|μ| >= 1 − tol)
_SAME_EIGENVALUE = 1e-12  # eigenvalues this close (relative) share one PBH rank test


def check_system(value: Any, param: str = "system") -> LinearSystem:
    """``value`` if it is a :class:`LinearSystem`, else ``ValueError`` naming ``param``."""
    if not isinstance(value, LinearSystem):
        raise ValueError(f"{param} must be a LinearSystem, got {type(value).__name__}")
    return value


def _freeze_state(obj: Any, state: dict[str, Any]) -> None:
    """``__setstate__`` of the frozen system classes: restore, then make every array read-only."""
    for name, value in state.items():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        object.__setattr__(obj, name, value)


def pbh_defects(F: np.ndarray, B: np.ndarray, *, side: str, unstable_only: bool) -> list[complex]:
    """Eigenvalues of F where the PBH rank test fails (empty list: the pair passes).

    Args:
        F: (n, n) transition.
        B: (m, n) output matrix (``side="rows"``: ``rank [F − μI; B] = n``, detectability) or
            (n, m) input matrix (``side="cols"``: ``rank [F − μI, B] = n``, stabilisability).
        side: ``"rows"`` or ``"cols"``.
        unstable_only: Test only ``|μ| > 1 + PBH_TOL`` (else also the marginal ``|μ| >= 1 − tol``).
    """
    n = F.shape[0]
    # Each block is scaled to max |entry| 1 (the rank is unchanged): a noise factor 1e10 times
    # F's entries (σ_v = 1e10) must not make F's own unit-size directions look like round-off.
    f_scale = max(1.0, float(np.abs(F).max()))
    b_max = float(np.abs(B).max()) if B.size else 0.0
    B = B / b_max if b_max > 0.0 else B
    bad = []
    tested: dict[complex, bool] = {}  # a repeated eigenvalue (F = I on the grids) tested once
    for mu in np.linalg.eigvals(F):
        radius = abs(mu)
        if (radius <= 1.0 + PBH_TOL) if unstable_only else (radius < 1.0 - PBH_TOL):
            continue
        same = next((v for v in tested if abs(mu - v) <= _SAME_EIGENVALUE * max(1.0, radius)), None)
        if same is None:
            shifted = (F - mu * np.eye(n)) / f_scale
            M = np.vstack([shifted, B]) if side == "rows" else np.hstack([shifted, B])
            same = complex(mu)
            tested[same] = bool(np.linalg.svd(M, compute_uv=False)[n - 1] <= PBH_TOL)  # rank < n
        if tested[same]:
            bad.append(complex(mu))
    return bad


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """``Q^{1/2}`` (symmetric square root of a PSD matrix; rounding negatives clipped)."""
    w, v = np.linalg.eigh(0.5 * (Q + Q.T))
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


def _fmt_eig(mu: complex) -> str:
    return f"{mu.real:.6g}" if abs(mu.imag) < 1e-12 else f"{mu.real:.6g}{mu.imag:+.6g}j"


def check_detectable(F: np.ndarray, H: np.ndarray, what: str) -> None:
    """``ValueError`` naming ``what`` and the eigenvalue unless ``(F, H)`` is detectable."""
    bad = pbh_defects(F, H, side="rows", unstable_only=False)
    if bad:
        raise ValueError(
            f"(F, H) of {what} is not detectable: the mode of F with eigenvalue "
            f"{_fmt_eig(bad[0])} (|μ| >= 1) is not seen by any sensor (PBH rank test, tolerance "
            f"{PBH_TOL:g}); its error covariance would grow without bound. Add a sensor that "
            "observes it or make the mode stable"
        )


@dataclass(frozen=True, eq=False)
class Sensor:
    """One sensor ``z_i = H_i x + w_i``, ``w_i ~ N(0, R_i)``.

    Attributes:
        H: (nz_i, n) measurement matrix.
        R: (nz_i, nz_i) noise covariance, symmetric positive definite.
        name: Label used in renders and reports.
    """

    H: np.ndarray
    R: np.ndarray
    name: str = ""

    def __post_init__(self) -> None:
        H = as_matrix("Sensor.H", self.H)
        if H.size == 0:
            raise ValueError(f"Sensor.H must be a non-empty matrix, got shape {H.shape}")
        R = as_matrix("Sensor.R", self.R, shape=(H.shape[0], H.shape[0]))
        check_psd("Sensor.R", R, strict=True)
        check_magnitude("Sensor.R", R)
        with np.errstate(all="ignore"):
            information = H.T @ np.linalg.solve(R, H)
        check_magnitude("Sensor.R", information, "is too small for its H: its information H' R⁻¹ H")
        if not isinstance(self.name, str):
            raise ValueError(f"Sensor.name must be a string, got {self.name!r}")
        object.__setattr__(self, "H", H)
        object.__setattr__(self, "R", R)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickling (and ``copy.deepcopy``) keeps the arrays read-only."""
        _freeze_state(self, state)

    @property
    def dim(self) -> int:
        """Number of measurement components ``nz_i``."""
        return self.H.shape[0]


@dataclass(frozen=True, eq=False)
class LinearSystem:
    """``x[k+1] = F x[k] + G u + v``, ``v ~ N(0, Q)``, observed by independent sensors.

    Attributes:
        F: (n, n) state transition.
        Q: (n, n) process noise covariance, symmetric PSD.
        sensors: The M sensors; their noises are independent of each other.
        x0: (n,) prior mean of the initial state (default zeros).
        P0: (n, n) prior covariance of the initial state, symmetric PD (default identity).
        G: (n, p) input matrix (default none).
        u: (p,) constant known input (default zeros).
        T: Sampling period; used by the position/velocity power weighting Ω.
        name: Label.

    Derived (computed in ``__post_init__``):
        n, M, nz: state size, number of sensors, stacked measurement size.
        H: (nz, n) stacked measurement matrix; R: (nz, nz) block-diagonal noise covariance.
        J: (M, n, n) per-sensor information ``H_i' R_i⁻¹ H_i``.
        HtRinv: (n, nz) ``H' R⁻¹`` (block structure makes column blocks per sensor).
        row_sensor: (nz,) index of the sensor that owns each stacked measurement row.
        Gu: (n,) the deterministic input term ``G u``.
    """

    F: np.ndarray
    Q: np.ndarray
    sensors: tuple[Sensor, ...]
    x0: np.ndarray | None = None
    P0: np.ndarray | None = None
    G: np.ndarray | None = None
    u: np.ndarray | None = None
    T: float = 1.0
    name: str = "custom"
    n: int = field(init=False)
    M: int = field(init=False)
    nz: int = field(init=False)
    H: np.ndarray = field(init=False, repr=False)
    R: np.ndarray = field(init=False, repr=False)
    J: np.ndarray = field(init=False, repr=False)
    HtRinv: np.ndarray = field(init=False, repr=False)
    row_sensor: np.ndarray = field(init=False, repr=False)
    Gu: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        F = as_matrix("LinearSystem.F", self.F)
        n = F.shape[0]
        if F.size == 0:
            raise ValueError(
                f"LinearSystem.F must be a non-empty square matrix, got shape {F.shape}"
            )
        if F.shape != (n, n):
            raise ValueError(f"LinearSystem.F must be square, got shape {F.shape}")
        Q = as_matrix("LinearSystem.Q", self.Q, shape=(n, n))
        check_psd("LinearSystem.Q", Q)
        check_magnitude("LinearSystem.Q", Q)
        zero_d = isinstance(self.sensors, np.ndarray) and self.sensors.ndim == 0  # not iterable
        if (
            isinstance(self.sensors, Sensor | str)
            or zero_d
            or not isinstance(self.sensors, Iterable | None)
        ):
            raise ValueError(
                "LinearSystem.sensors must be a sequence of Sensor, got "
                f"{type(self.sensors).__name__} (wrap a single sensor as (sensor,))"
            )
        if not isinstance(self.name, str):
            raise ValueError(f"LinearSystem.name must be a string, got {self.name!r}")
        sensors = tuple(self.sensors) if self.sensors is not None else ()
        if not sensors:
            raise ValueError("LinearSystem.sensors must hold at least one Sensor")
        for i, s in enumerate(sensors):
            if not isinstance(s, Sensor):
                raise ValueError(
                    f"LinearSystem.sensors[{i}] must be a Sensor, got {type(s).__name__}"
                )
            if s.H.shape[1] != n:
                raise ValueError(
                    f"LinearSystem.sensors[{i}].H must have {n} columns to match F, "
                    f"got shape {s.H.shape}"
                )
        x0 = as_vector("LinearSystem.x0", np.zeros(n) if self.x0 is None else self.x0, n)
        P0 = as_matrix("LinearSystem.P0", np.eye(n) if self.P0 is None else self.P0, shape=(n, n))
        check_psd("LinearSystem.P0", P0, strict=True)
        check_magnitude("LinearSystem.P0", P0)
        with np.errstate(all="ignore"):
            information = np.linalg.inv(P0)
        check_magnitude("LinearSystem.P0", information, "is too small: its information P0⁻¹")
        if self.G is None:
            if self.u is not None:
                raise ValueError("LinearSystem.u was given without LinearSystem.G")
            Gu = np.zeros(n)
        else:
            G = as_matrix("LinearSystem.G", self.G, shape=(n, None))
            u = as_vector(
                "LinearSystem.u", np.zeros(G.shape[1]) if self.u is None else self.u, G.shape[1]
            )
            object.__setattr__(self, "G", G)
            object.__setattr__(self, "u", u)
            Gu = G @ u
        T = check_positive("LinearSystem.T", self.T)

        H = np.vstack([s.H for s in sensors])
        R = block_diag(*[s.R for s in sensors])
        Rinv = block_diag(*[np.linalg.inv(s.R) for s in sensors])
        J = np.stack([s.H.T @ np.linalg.solve(s.R, s.H) for s in sensors])
        row_sensor = np.concatenate([np.full(s.dim, i) for i, s in enumerate(sensors)])
        check_detectable(F, H, f"system {self.name!r}")
        bad = pbh_defects(F, noise_factor(Q), side="cols", unstable_only=True)
        if bad:
            raise ValueError(
                f"(F, Q^(1/2)) of system {self.name!r} is not stabilisable: the unstable mode "
                f"of F with eigenvalue {_fmt_eig(bad[0])} (|μ| > 1) receives no process noise "
                f"(PBH rank test, tolerance {PBH_TOL:g}); the Riccati equation then has no "
                "stabilising solution. Give Q a component along that mode"
            )
        for name, value in (
            ("F", F),
            ("Q", Q),
            ("sensors", sensors),
            ("x0", x0),
            ("P0", P0),
            ("n", n),
            ("M", len(sensors)),
            ("nz", H.shape[0]),
            ("H", H),
            ("R", R),
            ("J", 0.5 * (J + J.transpose(0, 2, 1))),
            ("HtRinv", H.T @ Rinv),
            ("row_sensor", row_sensor),
            ("Gu", Gu),
            ("T", T),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickling (and ``copy.deepcopy``) keeps the arrays read-only."""
        _freeze_state(self, state)

    def row_mask(self, sensor_mask: np.ndarray) -> np.ndarray:
        """Expand a (..., M) per-sensor mask to the (..., nz) stacked measurement rows."""
        return np.asarray(sensor_mask)[..., self.row_sensor]

    def sensor_slice(self, i: int) -> slice:
        """Rows of the stacked measurement vector that belong to sensor ``i``."""
        start = sum(s.dim for s in self.sensors[:i])
        return slice(start, start + self.sensors[i].dim)
