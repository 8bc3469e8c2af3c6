"""The attack-model interface: what the attacker's action means."""

from __future__ import annotations

import numbers
from abc import ABC, abstractmethod
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from fdia_env.backend import NUMPY, ONE, Backend
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class AttackEffect(NamedTuple):
    """What an attack does to one filter step.

    Attributes:
        attacked: Bitmask of the sensors whose measurement carries a bias this step (bit i set =
            sensor i, 0-based); see :func:`bits_to_mask`.
        sigma: (nz, nz) bias covariance over the stacked measurement, or None when the bias
            value never matters (e.g. it is always detected and dropped) or is zero.
        probability: Probability that the bias is injected at all this step (nature draws
            H1 with it; 1 = always).
    """

    attacked: int
    sigma: np.ndarray | None = None
    probability: float = 1.0

    # a NamedTuple (immutable, built every step: cheaper than a frozen dataclass)


def bits_to_mask(bits: int, M: int) -> np.ndarray:
    """Bit ``i`` of ``bits`` set means sensor ``i``: returns an (M,) bool array (any M)."""
    if M <= 62:
        return (int(bits) >> np.arange(M)) & 1 == 1
    raw = np.frombuffer(int(bits).to_bytes((M + 7) // 8, "little"), dtype=np.uint8)
    return np.unpackbits(raw, bitorder="little")[:M].astype(bool)


def bit_array(values: Any, M: int) -> np.ndarray:
    """(B,) sensor bitmasks as int64 for M <= 62, else as Python ints in an object array.

    The batched models keep one bitmask per member; beyond 62 sensors a bitmask no longer fits
    an int64, and numpy's object arrays keep the same ``&``, ``|``, ``~``, ``>>`` semantics.
    """
    if M <= 62:
        return np.asarray(values, dtype=np.int64)
    out = np.empty(len(values), dtype=object)
    out[:] = [int(v) for v in values]
    return out


def same_sensors(xp: Backend, batch: int, bits: int, M: int) -> Any:
    """Every member's sensor set = ``bits``, as the backend ``xp`` holds sensor sets.

    numpy: (B,) bitmasks (:func:`bit_array`); torch: (B, M) boolean masks; the batch of one
    (:data:`~fdia_env.backend.ONE`): the Python int itself.
    """
    if xp is ONE:
        return int(bits)
    if xp is NUMPY:
        return bit_array([bits] * batch, M)
    return xp.asarray(np.broadcast_to(bits_to_mask(bits, M), (batch, M)).copy())


def mask_array_to_bits(masks: np.ndarray) -> np.ndarray:
    """(B, M) booleans -> (B,) bitmasks (:func:`bit_array` dtype)."""
    masks = np.asarray(masks, dtype=bool)
    M = masks.shape[1]
    if M <= 62:
        return masks.astype(np.int64) @ (np.int64(1) << np.arange(M, dtype=np.int64))
    packed = np.packbits(masks, axis=1, bitorder="little")
    return bit_array([int.from_bytes(row.tobytes(), "little") for row in packed], M)


def mask_to_bits(mask: np.ndarray) -> int:
    """Inverse of :func:`bits_to_mask`."""
    return sum(1 << int(i) for i in np.flatnonzero(mask))


class BatchOfOneModel:
    """The single-env calls of a model family run its batched code on the batch of one.

    A family's base class (:class:`AttackModel`, ``DefenseModel``) lists its single-env calls in
    ``_SINGLE_ENV_CALLS`` and writes them on :data:`~fdia_env.backend.ONE`; a subclass that
    writes one of them is refused, since its logic belongs in the ``batch_*`` methods.
    """

    _SINGLE_ENV_CALLS: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Refuse a subclass that writes a single-env call: its logic goes in ``batch_*``."""
        super().__init_subclass__(**kwargs)
        if "_SINGLE_ENV_CALLS" in vars(cls):  # the family's base writes them
            return
        written = [name for name in cls._SINGLE_ENV_CALLS if name in vars(cls)]
        if written:
            family = next(c for c in cls.__mro__ if "_SINGLE_ENV_CALLS" in vars(c))
            raise TypeError(
                f"{cls.__name__} defines {written}: a model implements only its batched "
                "methods (batch_reset, batch_apply, batch_features, ...); the single env runs "
                f"them on the batch of one (see {family.__name__})"
            )

    def reset(self) -> None:
        """Start an episode (the batch of one, :data:`~fdia_env.backend.ONE`)."""
        self.xp = ONE
        self.batch_reset(1)  # type: ignore[attr-defined]  # each family's base declares it


class AttackModel(ABC, BatchOfOneModel):
    """Owns the attacker's action space, its observation features and how an action acts.

    Models are built with their own parameters only; the environment calls :meth:`bind`
    once with the system and episode spec, which builds the spaces.

    **One implementation per model.** A model writes its logic once, in the ``batch_*`` methods
    over (B, ...) arrays of the backend :attr:`xp` (numpy, or torch for the models that list it
    in :attr:`batch_backends`); they are what the native vector envs (:mod:`fdia_env.vector`)
    call. The single env (:class:`~fdia_env.envs.parallel.FdiaParallelEnv` and its views) is
    the batch of one: :meth:`reset`, :meth:`features`, :meth:`action_mask`, :meth:`apply`,
    :meth:`info`, :meth:`private_info`, :meth:`draw_nature` and :meth:`observe_opponent` below
    run the ``batch_*`` methods on the backend :data:`~fdia_env.backend.ONE`, where the batch
    axis is dropped: a (B,) array is member 0's Python scalar, a (B, ...) array member 0's
    (...) numpy array (see :mod:`fdia_env.backend.one`). A subclass overrides none of them. So
    that one code runs on every backend, a model indexes the batch axis only through
    ``xp.col`` (``x[:, None]``) and ``xp.member`` (``x[i]``), and keeps lookup tables built
    once (in :meth:`bind` or on first use) rather than per reset or step.
    A model instance serves one env at a time (the native vector env built from a parallel
    env takes over its models and resets them as a batch of B).
    """

    name: str = "attack"
    reset_options: tuple[str, ...] = ()  # keys of reset(options=...) the model reads
    action_space: spaces.Space
    feature_low: np.ndarray
    feature_high: np.ndarray

    @abstractmethod
    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Attach to a system and episode; build spaces (and lookup tables) here, once."""

    def check_reset_options(self, options: dict[str, Any]) -> None:
        """Raise ``ValueError`` for a bad value of one of :attr:`reset_options`.

        Called before reset changes anything.
        """

    _SINGLE_ENV_CALLS = (
        "reset",
        "draw_nature",
        "features",
        "action_mask",
        "apply",
        "apply_checked",
        "info",
        "private_info",
        "observe_opponent",
    )

    # --- the single env: the batch of one ---------------------------------------------------
    def draw_nature(self, rng: np.random.Generator, options: dict[str, Any]) -> None:
        """Nature's draws of an episode (e.g. the attacker's type), at every reset.

        Called after the simulation's own draws, with the env's generator and reset's
        ``options`` (the keys in :attr:`reset_options`).
        """
        self.batch_draw_nature([rng], None, options)

    def features(self) -> list[float]:
        """Model-specific observation features, scaled to order one."""
        values = self.batch_features()
        return values if type(values) is list else values.tolist()

    def action_mask(self) -> np.ndarray | None:
        """Legal discrete actions (int8, 1 = legal) or None when every action is legal."""
        return self.batch_action_mask()

    def apply(self, action: Any) -> AttackEffect:
        """Validate ``action`` (``ValueError`` if outside the space) and act."""
        return self.apply_checked(check_space(self.action_space, action, "attacker"))

    def apply_checked(self, action: Any) -> AttackEffect:
        """Act on an action already checked against :attr:`action_space` (the env's step)."""
        bits, sigma = self.batch_apply(action)
        probability = self.batch_probability()
        return AttackEffect(int(bits), sigma, 1.0 if probability is None else float(probability))

    def info(self) -> dict[str, Any]:
        """Per-step information for the ``infos`` dict.

        The same keys after :meth:`reset` and after every step, each value a Python scalar or a
        fixed-shape numpy array (so vector envs and client libraries can batch them); after
        :meth:`reset` the values describe "nothing happened yet" (zeros, the full budget).
        """
        return self.batch_info()

    def private_info(self) -> dict[str, Any]:
        """Information only the attacker receives (its infos, not the defender's)."""
        return self.batch_private_info()

    def observe_opponent(self, other: Any) -> None:
        """Called after each step with the other player's model (repeated games use it)."""
        self.batch_observe_opponent(other)

    # --- the one implementation, over batches ------------------------------------------------
    # The batch state lives in attributes prefixed ``b_``. The batch arrays belong to the
    # backend ``xp`` (the vector env sets it before ``batch_reset``; the single env uses numpy);
    # ``batch_backends`` names the backends a model implements. On both backends the env has
    # checked the actions' type, shape and range (and on torch the device) before
    # ``batch_apply``, once per step (fdia_env.actions): ``batch_apply`` takes them as
    # valid. On torch, sensor sets may be (B, M) boolean masks, not bitmasks. The arrays a
    # ``batch_*`` method returns are not changed afterwards (a step makes new ones).

    xp: Backend = NUMPY
    batch_backends: tuple[str, ...] = ("numpy",)

    @abstractmethod
    def batch_reset(self, batch: int, where: np.ndarray | None = None) -> None:
        """Start episodes for the batch members ``where`` (all when None) of ``batch``."""

    def batch_draw_nature(
        self,
        rngs: list[np.random.Generator],
        where: np.ndarray | None = None,
        options: dict[str, Any] | None = None,
    ) -> None:
        """Nature's draws of the members ``where``: member ``i`` draws from ``rngs[i]``."""

    def batch_private_info(self) -> dict[str, np.ndarray]:
        """(B, ...) values of the attacker's private infos."""
        return {}

    def batch_observe_opponent(self, other: Any) -> None:
        """Called after each step with the other player's model (repeated games use it)."""

    @abstractmethod
    def batch_features(self) -> np.ndarray:
        """(B, f) features of every batch member."""

    def batch_action_mask(self) -> np.ndarray | None:
        """(B, A) legal actions (int8, a new array) or None."""
        return None

    def batch_info(self) -> dict[str, np.ndarray]:
        """Each info key's values of the B members stacked on axis 0."""
        return {}

    @abstractmethod
    def batch_apply(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Act on checked (B, ...) actions: ``(attacked bits (B,), Σ (B, nz, nz) or None)``."""

    def batch_probability(self) -> np.ndarray | None:
        """(B,) probabilities that the last :meth:`batch_apply` injects its bias (None = 1)."""
        return None


def check_space(space: spaces.Space, action: Any, who: str) -> Any:
    """The meaning of ``action`` if ``space`` accepts it, else ``ValueError`` naming ``who``.

    The models' own check for a direct call: the envs' rule,
    :func:`fdia_env.actions.check_action` (Gymnasium's ``contains``).
    """
    from fdia_env.actions import check_action

    return check_action(space, action, who)


def as_index(action: Any) -> int | None:
    """An integer action as int (numpy integers and 1-element integer arrays too), else None."""
    if isinstance(action, numbers.Integral) and not isinstance(action, bool):
        return int(action)
    if (
        isinstance(action, np.ndarray)
        and action.size == 1
        and np.issubdtype(action.dtype, np.integer)
    ):
        return int(action.reshape(()))
    return None
