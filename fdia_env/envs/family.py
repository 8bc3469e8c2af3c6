"""What the random system families share: their numbered systems and their range checks.

A family (:class:`~fdia_env.envs.grid_family.GridFamily`,
:class:`~fdia_env.envs.system_family.TrackingFamily`) draws a
:class:`~fdia_env.systems.LinearSystem` with ``draw(rng)``; system number ``k`` is the draw of
``numpy.random.default_rng(k)``, and its scenario adds the family's budget and horizon.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from fdia_env._validation import check_int
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem


def check_range(
    name: str, value: Any, lower: float = 0.0, closed: bool = False
) -> tuple[float, float]:
    """``value`` as a ``(low, high)`` pair of floats with ``lower < low <= high``.

    Args:
        name: The parameter's name, for the error.
        value: The pair to check.
        lower: The bound below ``low``.
        closed: Whether ``low`` may equal ``lower``.

    Raises:
        ValueError: Naming ``name``, for anything but two finite numbers in that order.
    """
    ok = isinstance(value, (tuple, list)) and len(value) == 2
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ok = ok and all(math.isfinite(v) for v in value) and value[0] <= value[1]
    ok = ok and (value[0] >= lower if closed else value[0] > lower)
    if not ok:
        raise ValueError(
            f"{name} must be a (low, high) pair of finite numbers with "
            f"{lower:g} {'<=' if closed else '<'} low <= high, got {value!r}"
        )
    return float(value[0]), float(value[1])


class NumberedFamily:
    """Base of a frozen family dataclass with ``budget``, ``horizon`` and ``draw(rng)``.

    Its scenarios are named after the class (``TrackingFamily``: ``"tracking-family-<seed>"``);
    a subclass may extend :meth:`describe` (their descriptions).
    """

    budget: int
    horizon: int

    def draw(self, rng: np.random.Generator) -> LinearSystem:
        """One system, drawn with ``rng`` (written by each family)."""
        raise NotImplementedError(f"{type(self).__name__} must implement draw()")

    @property
    def scenario_prefix(self) -> str:
        """The scenarios' name before the seed: the class name in kebab case."""
        return re.sub(r"(?<!^)(?=[A-Z])", "-", type(self).__name__).lower()

    def describe(self) -> str:
        """The family in words, for its scenarios' descriptions."""
        return self.scenario_prefix.replace("-", " ")

    def system(self, seed: int) -> LinearSystem:
        """System number ``seed``: ``draw(numpy.random.default_rng(seed))``."""
        return self.draw(np.random.default_rng(check_int("seed", seed, minimum=0)))

    def scenario(self, seed: int) -> Scenario:
        """System number ``seed`` with the family's budget and horizon (for the solvers)."""
        return Scenario(
            f"{self.scenario_prefix}-{seed}",
            self.system(seed),
            f"{self.describe()} system {seed}",
            budget=self.budget,
            horizon=self.horizon,
        )
