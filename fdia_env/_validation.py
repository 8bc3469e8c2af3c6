"""Input checks shared by every public constructor: clear errors that name the parameter."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

_SYM_RTOL = 1e-9

# Largest admissible attack power a² (a covariance trace). Beyond it sums such as Pzz0 + Σ and
# the symmetrisation (A + A')/2 can overflow; the detection numerics are validated up to it
# (tests/test_numerics.py). Physically every error limit is reached long before (docs/math.md §3).
MAX_POWER = 1e300

# Largest admissible size of an injection or gain parameter (a bias in pu or in innovation
# deviations, a magnitude, a gain spread): the statistics, errors and KL divergences square it
# and multiply it by the system's constants, so 1e100 keeps them (~1e200 and up to 1e100 of
# system scale and window sums on top) inside float64's 1.8e308.
MAX_SCALE = 1e100

# Largest admissible entry of a system's covariances (Q, R, P0) and informations (H' R⁻¹ H,
# P0⁻¹). The filter is exact at any scale up to it (the covariances of a system whose Q, R and
# P0 are scaled by s are s times those at scale 1); the factor of ~1.8e4 left to float64's
# 1.8e308 keeps sums over the state, the error's growth over a window and sampled squared errors
# finite (a trace, or a squared error, of covariances near 1e308 overflows). An information of
# 1e304 is a covariance of 1e-304 seen from the other side: its inverse must stay a normal float.
MAX_COVARIANCE = 1e304


def as_float_array(name: str, value: Any, expected: str) -> np.ndarray:
    """``value`` as a float64 array (a copy), or ``ValueError`` naming ``name``.

    Args:
        name: Parameter name used in the error message.
        value: Anything ``np.array`` accepts.
        expected: What ``value`` should be, for the message ``"<name> must be <expected>,
            got <value>"`` (a ragged list, a string, an object numpy cannot convert, a complex
            array).

    Example:
        >>> as_float_array("x", [1, 2], "a vector").dtype
        dtype('float64')
    """
    dtype = getattr(value, "dtype", None)
    if dtype is not None and np.issubdtype(dtype, np.complexfloating):
        # numpy would drop the imaginary part with only a ComplexWarning
        raise ValueError(f"{name} must be {expected}, got a complex array: {value!r}")
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be {expected}, got {value!r}") from exc


def as_matrix(
    name: str, value: Any, shape: tuple[int | None, int | None] | None = None
) -> np.ndarray:
    """Convert ``value`` to a finite, read-only float64 2-D array or raise ``ValueError``.

    Args:
        name: Parameter name used in error messages.
        value: Anything ``np.asarray`` accepts; scalars become 1x1 and vectors 1xn.
        shape: Required shape; ``None`` entries are free.

    Returns:
        A read-only float64 copy of shape ``(rows, cols)``.
    """
    arr = as_float_array(name, value, "a numeric matrix")
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D matrix, got an array of shape {arr.shape}")
    if shape is not None:
        for axis, want in enumerate(shape):
            if want is not None and arr.shape[axis] != want:
                raise ValueError(f"{name} must have shape {_fmt_shape(shape)}, got {arr.shape}")
    check_finite(name, arr)
    arr.setflags(write=False)
    return arr


def as_vector(name: str, value: Any, size: int) -> np.ndarray:
    """Convert ``value`` to a finite, read-only float64 vector of length ``size``."""
    arr = as_float_array(name, value, "a numeric vector").reshape(-1)
    if arr.size != size:
        raise ValueError(f"{name} must have {size} entries, got {arr.size}")
    check_finite(name, arr)
    arr.setflags(write=False)
    return arr


def check_finite(name: str, arr: np.ndarray) -> None:
    """Raise ``ValueError`` if ``arr`` holds NaN or infinity."""
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf), got {np.asarray(arr).tolist()}")


def check_square(name: str, arr: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``arr`` is square."""
    if arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must be square, got shape {arr.shape}")


def check_symmetric(name: str, arr: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``arr`` is symmetric to a relative tolerance."""
    check_square(name, arr)
    scale = max(1.0, float(np.max(np.abs(arr))))
    if not np.allclose(arr, np.swapaxes(arr, -1, -2), rtol=0.0, atol=_SYM_RTOL * scale):
        raise ValueError(f"{name} must be symmetric, got {np.asarray(arr).tolist()}")


def check_psd(name: str, arr: np.ndarray, *, strict: bool = False) -> None:
    """Raise ``ValueError`` unless ``arr`` is symmetric PSD (positive definite if ``strict``)."""
    check_symmetric(name, arr)
    eig = np.linalg.eigvalsh(arr)
    scale = max(1.0, float(np.max(np.abs(eig)))) if eig.size else 1.0
    lowest = float(eig.min()) if eig.size else 0.0
    if strict and lowest <= 0.0:
        raise ValueError(
            f"{name} must be positive definite; its smallest eigenvalue is {lowest:.6g}"
        )
    if not strict and lowest < -1e-10 * scale:
        raise ValueError(
            f"{name} must be positive semidefinite; its smallest eigenvalue is {lowest:.6g}"
        )


def check_magnitude(name: str, arr: np.ndarray, what: str = "entries") -> None:
    """Raise ``ValueError`` unless every entry of ``arr`` is at most :data:`MAX_COVARIANCE`.

    Args:
        name: The parameter, as the message names it.
        arr: The covariance (or the information derived from it) to check.
        what: What of ``name`` ``arr`` is, as the message says it (``"entries"``, or e.g.
            ``"is too small for its H: its information H' R⁻¹ H"``).
    """
    largest = float(np.max(np.abs(arr))) if np.size(arr) else 0.0
    if not largest <= MAX_COVARIANCE:  # NaN/inf too
        raise ValueError(
            f"{name} {what} must be at most {MAX_COVARIANCE:g} in magnitude (a filter's "
            f"covariances and informations inside float64's range with room for sums and "
            f"squared errors), got {largest:g}"
        )


def check_int(
    name: str, value: Any, *, minimum: int | None = None, maximum: int | None = None
) -> int:
    """Return ``value`` as int if it is an integer within bounds, else raise ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {value}")
    return value


def check_positive(name: str, value: Any, maximum: float | None = None) -> float:
    """Return ``value`` as float if it is finite and > 0 (and <= ``maximum``), else raise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name} must satisfy 0 < {name} <= {maximum:g}, got {value:g}")
    return value


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ``ValueError`` listing them."""
    # the type test first: ``array in choices`` compares elementwise and raises its own error
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


def check_agent(agent: Any, possible_agents: list[str]) -> str:
    """Return ``agent`` if it is one of the env's players, else raise ``ValueError`` naming them.

    Any type is accepted (an unhashable one fails with the same message).
    """
    if not (isinstance(agent, str) and agent in possible_agents):
        raise ValueError(f"agent must be one of {possible_agents}, got {agent!r}")
    return agent


def _fmt_shape(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"


def check_power(name: str, value: Any, *, allow_zero: bool = False) -> float:
    """Attack power ``a²`` as a float in ``(0, MAX_POWER]`` (``[0, ...]`` if ``allow_zero``).

    Raises:
        ValueError: Naming ``name`` and the allowed range, for a non-number, NaN, inf, a value
            out of range or a bool.
    """
    low = "0 <=" if allow_zero else "0 <"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(
            f"{name} must be a number with {low} {name} <= {MAX_POWER:g}, got {value!r}"
        )
    value = float(value)
    ok = (value >= 0.0 if allow_zero else value > 0.0) and value <= MAX_POWER  # NaN fails
    if not ok:
        raise ValueError(f"{name} must satisfy {low} {name} <= {MAX_POWER:g}, got {value}")
    return value


def check_positions(
    name: str, value: Any, names: dict[str, int], count: int, kind: str
) -> np.ndarray:
    """Sorted unique positions named by ``value``: positions ``0..count−1`` or names.

    Args:
        name: The parameter's name, for the messages.
        value: One position or name, or a collection of them.
        names: Name → position of the items that have a name.
        count: How many items there are.
        kind: What an item is, in the messages (``"sensor"``, ``"meter"``).

    Returns:
        The (k,) int64 positions, sorted, without repeats.

    Raises:
        ValueError: Naming ``name``, for a value that is not a collection, an unknown name or
            position, or an item that is neither a position nor a name.
    """
    if isinstance(value, (str, int, np.integer)):
        value = [value]
    try:
        items = list(value)
    except TypeError as exc:
        raise ValueError(f"{name} must be a collection of {kind}s, got {value!r}") from exc
    out = []
    for item in items:
        known = isinstance(item, (str, int, np.integer)) and not isinstance(item, bool)
        if isinstance(item, str) and item in names:
            out.append(names[item])
        elif known and not isinstance(item, str) and 0 <= int(item) < count:
            out.append(int(item))
        elif known:
            raise ValueError(
                f"{name} holds an unknown {kind} {item!r}: {kind}s are positions "
                f"0..{count - 1} or names such as {list(names)[:4]}"
            )
        else:
            raise ValueError(
                f"{name} must hold {kind} positions (0..{count - 1}) or names, got {item!r}"
            )
    return np.unique(np.array(out, dtype=np.int64))
