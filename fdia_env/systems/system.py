"""Linear Gaussian systems and their sensors (MATH.md §1)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import block_diag

from fdia_env._validation import as_matrix, as_vector, check_psd


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
        R = as_matrix("Sensor.R", self.R, shape=(H.shape[0], H.shape[0]))
        check_psd("Sensor.R", R, strict=True)
        object.__setattr__(self, "H", H)
        object.__setattr__(self, "R", R)

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
        if F.shape != (n, n):
            raise ValueError(f"LinearSystem.F must be square, got shape {F.shape}")
        Q = as_matrix("LinearSystem.Q", self.Q, shape=(n, n))
        check_psd("LinearSystem.Q", Q)
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
        if not np.isfinite(self.T) or self.T <= 0:
            raise ValueError(f"LinearSystem.T must be a finite number > 0, got {self.T}")

        H = np.vstack([s.H for s in sensors])
        R = block_diag(*[s.R for s in sensors])
        Rinv = block_diag(*[np.linalg.inv(s.R) for s in sensors])
        J = np.stack([s.H.T @ np.linalg.solve(s.R, s.H) for s in sensors])
        row_sensor = np.concatenate([np.full(s.dim, i) for i, s in enumerate(sensors)])
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
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def row_mask(self, sensor_mask: np.ndarray) -> np.ndarray:
        """Expand a (..., M) per-sensor mask to the (..., nz) stacked measurement rows."""
        return np.asarray(sensor_mask)[..., self.row_sensor]

    def sensor_slice(self, i: int) -> slice:
        """Rows of the stacked measurement vector that belong to sensor ``i``."""
        start = sum(s.dim for s in self.sensors[:i])
        return slice(start, start + self.sensors[i].dim)
