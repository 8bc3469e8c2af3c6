"""One set of option checks for ``agents``: training options, hyperparameters, configs.

Every check raises with a message naming the option (as ``name`` or, for ``train.py``'s
options, ``name (--flag)``), the allowed values and the value given: a ``TypeError`` for a value
of the wrong kind (a bool is never a number), a ``ValueError`` for one outside the allowed
values. :mod:`agents.config` (``train.py``'s options), :mod:`agents.torch_ppo` (its config) and
the RLlib settings use these; the environments' own checks are ``fdia_env``'s.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable


def flag(name: str) -> str:
    """``learning_rate`` -> ``learning_rate (--learning-rate)``: the field and its CLI flag."""
    return f"{name} (--{name.replace('_', '-')})"


def check_number(
    name: str,
    value: object,
    kind: type,
    ok: Callable[[float], bool],
    allowed: str,
    label: str | None = None,
) -> None:
    """Raise unless ``value`` is a finite number of ``kind`` for which ``ok`` holds.

    Args:
        name: The option's field name.
        value: Its value.
        kind: ``int`` (an integer, numpy's included) or ``float`` (any real number).
        ok: The allowed values.
        allowed: Their description (``"> 0"``, ``"in (0, 1]"``).
        label: How the message names the option (default: ``name (--flag)``).

    Raises:
        TypeError: For a value that is not an integer (``kind=int``) or a real number.
        ValueError: For one outside the allowed values.
    """
    label = flag(name) if label is None else label
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{label} must be a number {allowed}, got {value!r}")
    if kind is int and not isinstance(value, numbers.Integral):
        raise TypeError(f"{label} must be an integer {allowed}, got {value!r}")
    if not math.isfinite(value) or not ok(value):
        raise ValueError(f"{label} must be {allowed}, got {value!r}")


def check_int(
    name: str, value: object, minimum: int, maximum: int | None = None, label: str | None = None
) -> int:
    """``value`` as an int, if it is an integer in ``[minimum, maximum]``.

    Raises:
        TypeError: For a value that is not an integer.
        ValueError: For one outside the range (the message names it: ``>= 1``, ``in [1, 8]``).
    """
    allowed = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
    check_number(
        name,
        value,
        int,
        lambda v: v >= minimum and (maximum is None or v <= maximum),
        allowed,
        name if label is None else label,
    )
    return int(value)


def check_real(
    name: str, value: object, ok: Callable[[float], bool], allowed: str, label: str | None = None
) -> float:
    """``value`` as a float, if it is a finite real number for which ``ok`` holds.

    Raises:
        TypeError: For a value that is not a real number.
        ValueError: For one that is not finite or not allowed.
    """
    check_number(name, value, float, ok, allowed, name if label is None else label)
    return float(value)


def check_choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    """Raise unless ``value`` is one of ``choices``.

    Raises:
        ValueError: Listing the choices.
    """
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{flag(name)} must be one of {', '.join(choices)}, got {value!r}")
