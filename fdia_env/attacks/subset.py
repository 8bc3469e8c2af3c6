"""Subset attack: the attacker picks a non-empty sensor subset and splits its power by a rule.

The power a² is split over the attacked subset A by one of the literature's rules for scalar
(position) sensors (docs/math.md §2.2, §5):

- ``"independent"`` (Prop. 2): all power on the smallest-variance sensor of A;
- ``"dependent"`` (Prop. 3): correlation 1 over A with ``σ_b,i = c_i a / ||c||``,
  ``c_i = (1/σ_i²) / Σ_{j∈A} (1/σ_j²)``.

Both give ``tr Σ_A = a²``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fdia_env._validation import check_choice, check_int, check_power
from fdia_env.attacks.base import AttackModel
from fdia_env.attacks.subsets import SubsetChoice
from fdia_env.backend import NUMPY, namespace
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

ALLOCATIONS = ("independent", "dependent")
MAX_GAME_SENSORS = 16  # the full game (every non-empty subset) up to this M


def sensor_sigmas(system: LinearSystem) -> np.ndarray:
    """(M,) noise standard deviations σ_i of a system of scalar sensors.

    Raises:
        ValueError: If a sensor has more than one measurement component.
    """
    for i, s in enumerate(system.sensors):
        if s.dim != 1:
            raise ValueError(
                "the game's allocation rules are defined for scalar sensors (one measurement "
                f"each); system.sensors[{i}] ({s.name or 'unnamed'}) has {s.dim} components. "
                "Use position sensors, or compute Σ with the trace-optimal rank-one attack "
                "(docs/math.md §2.2) yourself"
            )
    return np.sqrt(np.array([s.R[0, 0] for s in system.sensors]))


def attack_directions(system: LinearSystem, masks: np.ndarray, allocation: str) -> np.ndarray:
    """Unit vectors ``u_A`` with ``Σ_A = a² u_A u_A'`` for a batch of attacked subsets.

    Args:
        system: A system of scalar sensors (so measurement row i is sensor i).
        masks: (k, M) booleans, each row a non-empty attacked subset (numpy, or a torch tensor:
            the directions are then a tensor of its device).
        allocation: ``"independent"`` or ``"dependent"``.

    Returns:
        (k, M) directions: one-hot (independent) or ``∝ 1/σ_i²`` on A (dependent).
    """
    check_choice("allocation", allocation, ALLOCATIONS)
    xp = namespace(masks)
    sigma = xp.asarray(sensor_sigmas(system))
    masks = np.asarray(masks, dtype=bool) if xp is NUMPY else masks
    if masks.ndim != 2 or masks.shape[1] != system.M or not xp.all(masks.any(1)):
        raise ValueError(f"masks must be (k, {system.M}) booleans, every row non-empty")
    if allocation == "independent":
        # Prop. 2: the smallest-σ sensor of A takes all the power (argmin: the first on ties)
        u = xp.zeros(tuple(masks.shape))
        u[xp.arange(len(masks)), xp.where(masks, sigma, np.inf).argmin(1)] = 1.0
        return u
    # Prop. 3: σ_b,i = c_i a / ||c||, c ∝ 1/σ_i² on A; the normalisation of c cancels
    w = xp.where(masks, 1.0 / sigma**2, 0.0)
    if xp is NUMPY:
        return w / np.linalg.norm(w, axis=1, keepdims=True)
    return w / xp.sqrt(xp.sum(w * w, 1))[:, None]


def as_subset(subset: Sequence[int], M: int) -> tuple[int, ...]:
    """``subset`` as a sorted tuple of distinct sensor indices in [0, M), or ValueError."""
    try:
        items = tuple(int(i) for i in subset)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"subset must be a sequence of sensor indices, got {subset!r}") from exc
    if not items:
        raise ValueError("subset must hold at least one sensor index, got an empty subset")
    if any(i < 0 or i >= M for i in items) or len(set(items)) != len(items):
        raise ValueError(
            f"subset must hold distinct 0-based sensor indices in [0, {M - 1}], got {subset!r}"
        )
    return tuple(sorted(items))


def allocation_covariance(
    system: LinearSystem, subset: Sequence[int], power: float, allocation: str = "independent"
) -> np.ndarray:
    """Σ_A over the stacked measurement (nz, nz) for attacked ``subset`` (0-based sensors).

    Args:
        system: A system of scalar sensors.
        subset: Attacked sensors, 0-based indices (e.g. ``(0, 2)`` for z1z3), non-empty.
        power: a² = tr Σ_A (> 0).
        allocation: ``"independent"`` (Prop. 2) or ``"dependent"`` (Prop. 3).

    Returns:
        (nz, nz) rank-one ``a² u_A u_A'``, zero outside A.

    Raises:
        TypeError: If ``system`` is not a :class:`~fdia_env.systems.LinearSystem`.
        ValueError: Naming the parameter: an empty or out-of-range subset, power ≤ 0, an
            unknown allocation, a sensor that is not scalar.

    Example:
        >>> from fdia_env import scenarios
        >>> sys = scenarios.get("ch5-game").system
        >>> allocation_covariance(sys, (1, 2), 100.0).tolist()
        [[0.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 0.0]]
        >>> S = allocation_covariance(sys, (0, 1), 100.0, "dependent")
        >>> S.round(2).tolist()  # correlation 1, σ_b ∝ (1/9, 1/16)
        [[75.96, 42.73, 0.0], [42.73, 24.04, 0.0], [0.0, 0.0, 0.0]]
    """
    if not isinstance(system, LinearSystem):
        raise TypeError(f"system must be a LinearSystem, got {type(system).__name__}")
    power = check_power("power", power)
    check_choice("allocation", allocation, ALLOCATIONS)
    sensor_sigmas(system)
    mask = np.zeros((1, system.M), dtype=bool)
    mask[0, list(as_subset(subset, system.M))] = True
    u = attack_directions(system, mask, allocation)[0]
    return power * np.outer(u, u)


class SubsetAttack(SubsetChoice, AttackModel):
    """Attack a non-empty sensor subset with power a² split by ``allocation``.

    Action: ``Discrete(2**M − 1)``, index ``j`` = the j-th subset by size then lexicographic
    (:func:`fdia_env.attacks.subsets.subsets`); with ``max_subset_size=k`` only the subsets of
    at most k sensors, in the same order. Features: the defender's last subset as a 0/1
    indicator per sensor (all zeros before the first round).
    """

    name = "subset"

    def __init__(
        self, power: float, allocation: str = "independent", max_subset_size: int | None = None
    ) -> None:
        self.power = check_power("power", power)
        self.allocation = check_choice("allocation", allocation, ALLOCATIONS)
        if max_subset_size is not None:
            check_int("max_subset_size", max_subset_size, minimum=1)
        self._k = max_subset_size

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action over the attacker's subsets (at most ``max_subset_size`` sensors)."""
        try:  # checked here, not at the first step that attacks a vector sensor
            sensor_sigmas(system)
        except ValueError as exc:
            raise ValueError(
                f"scenario {system.name!r} cannot host the subset attack: {exc}"
            ) from exc
        self.bind_subsets(system.M, self._k, "attacker")
        self._system = system
        self._dirs = self._directions(system)  # (types, subsets, nz): Σ_A = a² u u'

    def _directions(self, system: LinearSystem) -> np.ndarray:
        """Every subset's allocation direction, one row of types (here the one allocation)."""
        return attack_directions(system, self._masks_np, self.allocation)[None]

    def sigma(self, j: int) -> np.ndarray:
        """Σ of subset index ``j`` (of the single env's type for a typed attack)."""
        kind = int(self.xp.member(self.b_type, 0)) if hasattr(self, "b_type") else 0
        u = self._dirs[kind, j]
        return self.power * np.outer(u, u)

    # --- batched (see AttackModel) ---------------------------------------------------------
    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Forget the last round of the members ``where``; nothing attacked yet."""
        xp = self.xp
        rebuild = where is None and self._b_xp is not xp
        super().batch_reset(batch, where)
        if where is None:
            self.b_attacked = xp.zeros((batch, self.M), dtype=xp.int8)
            self.b_type = xp.zeros(batch, dtype=xp.int64)  # the allocation rule's index
            if rebuild:
                self._b_dirs = xp.asarray(self._dirs)
        else:
            self.b_attacked[where] = 0

    def batch_apply(self, actions: Any) -> tuple[Any, Any]:
        """Σ_A of each member's subset (rank one, from its type's allocation direction)."""
        xp = self.xp
        j = xp.astype(actions, xp.int64)  # checked by the env
        self.b_last = j
        self.b_attacked = xp.astype(self._masks[j], xp.int8)
        u = self._b_dirs[self.b_type, j]  # (B, nz)
        return xp.take(self._bits_arr, j), self.power * (u[..., :, None] * u[..., None, :])

    def batch_info(self) -> dict[str, Any]:
        """``attacked``: (B, M) int8, 1 for each sensor of the subset attacked this step."""
        return {"attacked": self.xp.copy(self.b_attacked)}
