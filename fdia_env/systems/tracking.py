"""The 1-D target-tracking model used throughout the literature (docs/math.md §1)."""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Sequence

import numpy as np

from fdia_env._validation import check_positive
from fdia_env.systems.system import LinearSystem, Sensor


def _zero_d(value: object) -> bool:
    """A 0-d array: ``Iterable`` by type, but iterating it raises a bare ``TypeError``."""
    return isinstance(value, np.ndarray) and value.ndim == 0


def _variance(name: str, sigma: float, factor: float = 1.0) -> float:
    """``(factor · sigma)²`` as a finite positive float, else ``ValueError`` naming ``name``.

    ``sigma ** 2`` of a Python float raises a bare ``OverflowError`` above ~1.3e154 and
    underflows to 0 below ~1e-162; the variance must be a normal float64 in both directions.
    """
    with np.errstate(over="ignore", under="ignore"):
        value = float(np.float64(factor * sigma) ** 2)
    if not np.isfinite(value) or value < np.finfo(np.float64).tiny:
        scaled = "" if factor == 1.0 else f" with T (the largest entry of Q is (σ_v·{factor:g})²)"
        raise ValueError(
            f"{name} = {sigma:g}{scaled} gives a variance {value:g} outside float64's normal "
            f"range (about 2.2e-308 to 1.8e308): a standard deviation must lie roughly in "
            "[1e-154, 1e154]"
        )
    return value


def position_sensor(sigma: float, name: str = "") -> Sensor:
    """A position sensor ``H = [1, 0]`` with noise standard deviation ``sigma``."""
    sigma = check_positive("sigma", sigma)
    return Sensor(H=np.array([[1.0, 0.0]]), R=np.array([[_variance("sigma", sigma)]]), name=name)


def pv_sensor(sigma_p: float, sigma_vel: float, rho: float = 0.0, name: str = "") -> Sensor:
    """A position+velocity sensor ``H = I₂`` with std devs and position/velocity correlation.

    Args:
        sigma_p: Position noise standard deviation.
        sigma_vel: Velocity noise standard deviation.
        rho: Correlation coefficient in (-1, 1).
        name: Label.
    """
    sigma_p = check_positive("sigma_p", sigma_p)
    sigma_vel = check_positive("sigma_vel", sigma_vel)
    _variance("sigma_p", sigma_p)
    _variance("sigma_vel", sigma_vel)
    if isinstance(rho, bool) or not isinstance(rho, numbers.Real):
        raise ValueError(f"rho must be a number strictly between -1 and 1, got {rho!r}")
    rho = float(rho)
    if not -1.0 < rho < 1.0:  # also rejects NaN
        raise ValueError(f"rho must lie strictly between -1 and 1, got {rho}")
    c = rho * sigma_p * sigma_vel
    return Sensor(H=np.eye(2), R=np.array([[sigma_p**2, c], [c, sigma_vel**2]]), name=name)


def tracking_system(
    sigma_v: float,
    sigma_w: float | Sequence[float] | None = None,
    T: float = 1.0,
    *,
    sensors: Sequence[Sensor] | None = None,
    x0: Sequence[float] | None = None,
    P0: np.ndarray | None = None,
    name: str = "tracking",
) -> LinearSystem:
    """Discrete white-noise-acceleration model ``x = [position, velocity]'``.

    ``F = [[1, T], [0, 1]]``, ``Γ = [T²/2, T]'``, ``Q = σ_v² Γ Γ'``.

    Args:
        sigma_v: Process noise standard deviation σ_v (> 0).
        sigma_w: Standard deviations of position sensors, one per sensor; a single number is
            one position sensor (``tracking_system(0.5, 3.0)`` equals
            ``tracking_system(0.5, [3.0])``).
        T: Sampling period (> 0).
        sensors: Explicit sensors (e.g. from :func:`pv_sensor`); appended after ``sigma_w``'s.
        x0: Prior mean (default zeros).
        P0: Prior covariance (default identity).
        name: Label.

    Returns:
        The validated :class:`LinearSystem`.

    Example:
        >>> sys = tracking_system(sigma_v=0.5, sigma_w=[3, 4, 5], T=1)
        >>> sys.M, sys.n
        (3, 2)
    """
    sigma_v = check_positive("sigma_v", sigma_v)
    T = check_positive("T", T)
    all_sensors: list[Sensor] = []
    if isinstance(sigma_w, numbers.Real) and not isinstance(sigma_w, bool):
        sigma_w = [sigma_w]  # one position sensor
    elif sigma_w is not None and (
        isinstance(sigma_w, str) or _zero_d(sigma_w) or not isinstance(sigma_w, Iterable)
    ):
        raise ValueError(
            "sigma_w must be a number or a sequence of numbers > 0 (position-sensor standard "
            f"deviations), got {sigma_w!r}"
        )
    for i, s in enumerate(() if sigma_w is None else sigma_w):
        _variance(f"sigma_w[{i}]", check_positive(f"sigma_w[{i}]", s))
        all_sensors.append(position_sensor(s, name=f"z{i + 1}"))
    if sensors is not None:
        if (
            isinstance(sensors, Sensor | str)
            or _zero_d(sensors)
            or not isinstance(sensors, Iterable)
        ):
            raise ValueError(f"sensors must be a sequence of Sensor, got {type(sensors).__name__}")
        sensors = tuple(sensors)  # not ``sensors or ()``: an array has no truth value
        for i, s in enumerate(sensors):
            if not isinstance(s, Sensor):
                raise ValueError(
                    f"sensors must be a sequence of Sensor; sensors[{i}] is a {type(s).__name__}"
                )
        all_sensors.extend(sensors)
    if not all_sensors:
        raise ValueError("tracking_system needs sigma_w or sensors: got no sensor at all")
    gamma = np.array([[T**2 / 2.0], [T]])
    _variance("sigma_v", sigma_v, max(T**2 / 2.0, T))  # the largest entry of Q = σ_v² Γ Γ'
    q = _variance("sigma_v", sigma_v)
    with np.errstate(under="ignore"):
        Q = q * (gamma @ gamma.T)
    return LinearSystem(
        F=np.array([[1.0, T], [0.0, 1.0]]),
        Q=Q,
        sensors=tuple(all_sensors),
        x0=x0,
        P0=P0,
        T=T,
        name=name,
    )


def power_weight(system: LinearSystem) -> np.ndarray:
    """Ω of docs/math.md §2: 1 on position rows, T² on velocity rows of position+velocity sensors.

    For sensors that are neither position nor position+velocity, the weight is 1.
    """
    w = []
    for s in system.sensors:
        if s.H.shape == (2, 2) and np.allclose(s.H, np.eye(2)):
            w.extend([1.0, system.T**2])
        else:
            w.extend([1.0] * s.dim)
    return np.diag(w)
