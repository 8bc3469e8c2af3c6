"""The equivalent sensor of M sensors (docs/math.md §2.4).

M sensors with one common H are equivalent, for the Kalman filter, to one sensor

    H_e = H,   R_e = (Σ_i R_i⁻¹)⁻¹,   z_e = R_e Σ_i R_i⁻¹ z_i;

in general, when ``J = Σ_i H_i' R_i⁻¹ H_i`` is invertible (every step observes the whole state),

    H_e = I,   R_e = J⁻¹,   z_e = R_e Σ_i H_i' R_i⁻¹ z_i.

Both carry the same information ``H_e' R_e⁻¹ H_e = Σ_i H_i' R_i⁻¹ H_i``, so the filter's
covariances are identical, and the combined gain satisfies ``W_e C = W`` where ``C`` maps the
stacked measurement to ``z_e``: a bias ``b ~ N(0, Σ)`` on the sensors is a bias
``C b ~ N(0, C Σ C')`` on the equivalent sensor, which is how docs/math.md §2.2 reduces a
multi-sensor attack to a one-sensor one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baselines._inputs import resolve_system
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem, Sensor


@dataclass(frozen=True, eq=False)
class EquivalentSensor:
    """One sensor equivalent to all of a system's sensors.

    Attributes:
        H: (m, n) measurement matrix ``H_e``.
        R: (m, m) noise covariance ``R_e``.
        combine: (m, nz) ``C`` with ``z_e = C z`` for the stacked measurement z.
        identical: True for the common-H rule, False for the general ``H_e = I`` rule.
        original: The system the sensor replaces.
    """

    H: np.ndarray
    R: np.ndarray
    combine: np.ndarray
    identical: bool
    original: LinearSystem

    def sensor(self, name: str = "equivalent") -> Sensor:
        """The equivalent :class:`~fdia_env.systems.Sensor`."""
        return Sensor(H=self.H, R=self.R, name=name)

    def system(self) -> LinearSystem:
        """The original system with its sensors replaced by the equivalent one."""
        s = self.original
        return LinearSystem(
            F=s.F,
            Q=s.Q,
            sensors=(self.sensor(),),
            x0=s.x0,
            P0=s.P0,
            G=s.G,
            u=s.u,
            T=s.T,
            name=f"{s.name} (equivalent sensor)",
        )

    def bias_covariance(self, sigma: np.ndarray) -> np.ndarray:
        """``C Σ C'``: the equivalent sensor's bias covariance for sensor biases ``N(0, Σ)``."""
        out = self.combine @ np.asarray(sigma, dtype=np.float64) @ self.combine.T
        return 0.5 * (out + out.T)


def equivalent_sensor(system_or_scenario: str | Scenario | LinearSystem) -> EquivalentSensor:
    """The equivalent sensor of docs/math.md §2.4.

    Uses the common-H rule when every sensor has the same H, else the general rule.

    Raises:
        ValueError: When the sensors' H differ and ``Σ H_i' R_i⁻¹ H_i`` is singular (no single
            step observes the whole state, so no ``H_e = I`` sensor exists).

    Example:
        >>> eq = equivalent_sensor("ch2-position")
        >>> eq.identical, round(float(eq.R[0, 0]), 6)  # (1/3 + 1/4)⁻¹ = 12/7
        (True, 1.714286)
    """
    system = resolve_system(system_or_scenario).system
    H0 = system.sensors[0].H
    if all(np.array_equal(s.H, H0) for s in system.sensors):
        Rinv = [np.linalg.inv(s.R) for s in system.sensors]
        R_e = np.linalg.inv(sum(Rinv))  # R_e = (Σ R_i⁻¹)⁻¹
        R_e = 0.5 * (R_e + R_e.T)
        combine = R_e @ np.hstack(Rinv)  # z_e = R_e Σ R_i⁻¹ z_i
        return EquivalentSensor(H0, R_e, combine, True, system)
    J = system.J.sum(axis=0)  # Σ H_i' R_i⁻¹ H_i
    if np.linalg.matrix_rank(J) < system.n:
        raise ValueError(
            "equivalent_sensor needs sensors with one common H or an invertible "
            f"Σ H_i' R_i⁻¹ H_i; for system {system.name!r} that matrix is singular: {J.tolist()}"
        )
    R_e = np.linalg.inv(J)  # R_e = J⁻¹
    R_e = 0.5 * (R_e + R_e.T)
    return EquivalentSensor(np.eye(system.n), R_e, R_e @ system.HtRinv, False, system)
