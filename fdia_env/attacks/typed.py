"""Typed subset attack: nature draws the attacker's allocation rule (its type) each episode.

The incomplete-information sensor game of docs/math.md §5: the attacker is one of S types, here
allocation rules (``"independent"``, ``"dependent"``), drawn at every reset with ``priors``
from the env's seeded generator. The defender never observes the type; the attacker does when
``attacker_model="informed"`` (a one-hot ``type`` block at the end of its features) and does
not when ``"uninformed"`` (the literature's formulation, where its features are the untyped
game's).

>>> import numpy as np
>>> from fdia_env import scenarios
>>> from fdia_env.episode import EpisodeSpec
>>> attack = TypedSubsetAttack(100.0, ("independent", "dependent"), (0.25, 0.75))
>>> attack.bind(scenarios.get("ch5-game").system, EpisodeSpec(horizon=1, warmup="steady"))
>>> attack.reset()
>>> attack.draw_type(np.random.default_rng(0)), attack.features()
(1, [0.0, 0.0, 0.0, 0.0, 1.0])
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from fdia_env._validation import check_choice
from fdia_env.attacks.subset import (
    ALLOCATIONS,
    SubsetAttack,
    attack_directions,
)
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

ATTACKER_MODELS = ("informed", "uninformed")
TYPE_OPTION = "attacker_type"
"""``reset(options={"attacker_type": t})`` forces type ``t`` (a name in ``types`` or an index)."""


def check_types(types: Any) -> tuple[str, ...]:
    """``types`` as a tuple of distinct allocation rules, or ``ValueError`` naming it."""
    if isinstance(types, str) or not isinstance(types, Sequence) or len(types) == 0:
        raise ValueError(
            f"types must be a non-empty sequence of attack types from {list(ALLOCATIONS)}, "
            f"got {types!r}"
        )
    out = tuple(check_choice(f"types[{s}]", t, ALLOCATIONS) for s, t in enumerate(types))
    if len(set(out)) != len(out):
        raise ValueError(f"types must be distinct, got {list(out)}")
    return out


def check_priors(priors: Any, size: int) -> np.ndarray:
    """``priors`` as a read-only (size,) probability vector, or ``ValueError`` naming it.

    ``None`` gives the uniform prior. Entries must be finite and ≥ 0 and sum to 1 within 1e-9.
    """
    if priors is None:
        p = np.full(size, 1.0 / size)
    else:
        if isinstance(priors, str) or not isinstance(priors, Sequence | np.ndarray):
            raise ValueError(f"priors must be a sequence of {size} probabilities, got {priors!r}")
        if any(isinstance(v, bool) or not isinstance(v, numbers.Real) for v in priors):
            raise ValueError(f"priors must hold real numbers, got {list(priors)!r}")
        p = np.array(priors, dtype=np.float64)
        if p.shape != (size,):
            raise ValueError(
                f"priors must have one probability per type ({size}), got {p.size} entries"
            )
        if not np.all(np.isfinite(p)) or (p < 0).any():
            raise ValueError(f"priors must be finite and >= 0, got {p.tolist()}")
        if abs(p.sum() - 1.0) > 1e-9:
            raise ValueError(f"priors must sum to 1, got sum {p.sum()!r} ({p.tolist()})")
        p = p / p.sum()
    p.setflags(write=False)
    return p


class TypedSubsetAttack(SubsetAttack):
    """:class:`~fdia_env.attacks.subset.SubsetAttack` whose allocation rule nature draws.

    ``allocation`` is None (no single rule applies); ``type_index`` is the episode's type, an
    index into ``types``, drawn by :meth:`draw_type` after every reset.

    Features: the defender's last subset (as the untyped attack), then, for an informed
    attacker, the type as a one-hot vector of length S. Infos: the untyped ``attacked``; the
    type is a private info (:meth:`private_info`, the attacker's only).

    Args:
        power: Attack power a² (every type spends all of it).
        types: Distinct allocation rules, e.g. ``("independent", "dependent")``.
        priors: Probability of each type (default uniform).
        attacker_model: ``"informed"`` (the attacker observes its type) or ``"uninformed"``.
        max_subset_size: As :class:`~fdia_env.attacks.subset.SubsetAttack`.
    """

    # nature's draw: the members' numpy generators, or torch's one device generator
    batch_backends = ("numpy", "torch")

    name = "typed_subset"
    reset_options = (TYPE_OPTION,)

    def __init__(
        self,
        power: float,
        types: Sequence[str],
        priors: Sequence[float] | np.ndarray | None = None,
        attacker_model: str = "informed",
        max_subset_size: int | None = None,
    ) -> None:
        types = check_types(types)
        super().__init__(power, types[0], max_subset_size)
        self.allocation = None  # untyped consumers (payoff_matrix(..., allocation)) fail loudly
        self.types = types
        self.priors = check_priors(priors, len(types))
        self.attacker_model = check_choice("attacker_model", attacker_model, ATTACKER_MODELS)
        self.informed = attacker_model == "informed"
        cdf = np.cumsum(self.priors)
        cdf[-1] = 1.0  # u < 1 always lands on a type with positive prior
        self._cdf = cdf

    @property
    def n_types(self) -> int:
        """S, the number of types."""
        return len(self.types)

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """As the untyped attack; an informed attacker's features end with the type's one-hot."""
        super().bind(system, spec)
        if self.informed:
            S = self.n_types
            self.feature_low = np.concatenate([self.feature_low, np.zeros(S, np.float32)])
            self.feature_high = np.concatenate([self.feature_high, np.ones(S, np.float32)])
        self._eye = np.eye(self.n_types)

    def _directions(self, system: LinearSystem) -> np.ndarray:
        """Every subset's allocation direction under each type: (types, subsets, nz)."""
        return np.stack([attack_directions(system, self._masks_np, t) for t in self.types])

    def type_of(self, value: Any) -> int:
        """A type given by name (one of ``types``) or index, as an index; else ``ValueError``."""
        if isinstance(value, str):
            if value not in self.types:
                raise ValueError(f"{TYPE_OPTION} must be one of {list(self.types)}, got {value!r}")
            return self.types.index(value)
        if (
            isinstance(value, numbers.Integral)
            and not isinstance(value, bool)
            and 0 <= int(value) < self.n_types
        ):
            return int(value)
        raise ValueError(
            f"{TYPE_OPTION} must be one of {list(self.types)} or an index in "
            f"[0, {self.n_types}), got {value!r}"
        )

    def draw_type(self, rng: np.random.Generator, forced: Any = None) -> int:
        """The single env's draw of the episode's type (see :meth:`batch_draw_nature`)."""
        self.draw_nature(rng, {} if forced is None else {TYPE_OPTION: forced})
        return self.type_index

    @property
    def type_index(self) -> int:
        """The single env's type this episode (an index into ``types``)."""
        return int(self.xp.member(self.b_type, 0)) if hasattr(self, "b_type") else 0

    @property
    def current_type(self) -> str:
        """The single env's allocation rule this episode."""
        return self.types[self.type_index]

    def check_reset_options(self, options: dict[str, Any]) -> None:
        """A forced ``attacker_type`` must name a type (or index one)."""
        if TYPE_OPTION in options:
            self.type_of(options[TYPE_OPTION])

    # --- batched -------------------------------------------------------------------------------
    def batch_draw_nature(
        self,
        rngs: list[np.random.Generator] | Any,
        where: Any = None,
        options: dict[str, Any] | None = None,
    ) -> None:
        """Nature's draw of the type of the members ``where`` (all when None) with ``priors``.

        Member ``i`` takes one uniform from ``rngs[i]`` even when ``options["attacker_type"]``
        forces the type, so that the episode's other draws do not depend on forcing it. On
        torch, ``rngs`` is the device's one ``torch.Generator``: it draws B uniforms (one per
        member, kept only ``where``), so the types equal numpy's in distribution, and exactly
        when forced.
        """
        forced = (options or {}).get(TYPE_OPTION)
        if not isinstance(rngs, list):  # torch: one generator draws for every member
            xp = self.xp
            u = xp.uniform(rngs, self._batch)
            if forced is None:
                drawn = xp.minimum(xp.searchsorted(self._cdf, u), self.n_types - 1)
            else:
                drawn = xp.full(self._batch, self.type_of(forced), dtype=xp.int64)
            self.b_type = drawn if where is None else xp.where(where, drawn, self.b_type)
            return
        members = range(self._batch) if where is None else np.flatnonzero(where)
        types = []
        for i in members:
            drawn = int(np.searchsorted(self._cdf, rngs[i].random(), side="right"))
            types.append(drawn if forced is None else self.type_of(forced))
        if where is None:  # the whole batch: (B,) types, or the batch of one's scalar
            self.b_type = self.xp.from_members(types, self.xp.int64)
        else:
            self.b_type[np.flatnonzero(where)] = types

    def batch_features(self) -> np.ndarray:
        """(B, M [+ S]) the defender's last subsets, then (informed) each member's type."""
        if not self.informed:
            return self.b_opponent
        if isinstance(self.b_opponent, np.ndarray):  # numpy, or the batch of one
            return np.hstack([self.b_opponent, self._eye[self.b_type]])
        xp, M = self.xp, self.M  # torch: the one-hot rows of a device copy of the identity
        if getattr(self, "_eye_xp", None) is not xp:
            self._eye_b, self._eye_xp = xp.asarray(self._eye), xp
        out = xp.empty((self._batch, M + self.n_types))
        out[:, :M] = self.b_opponent
        out[:, M:] = xp.take(self._eye_b, self.b_type)
        return out

    def batch_private_info(self) -> dict[str, np.ndarray]:
        """``type``: (B,) each member's type index (in the attacker's infos only)."""
        return {"type": self.xp.copy(self.b_type)}
