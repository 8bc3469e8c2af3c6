"""Type, shape and value checks of actions, shared by every face of every env.

The models check what an action *means* (a bitmask within the budget, a threshold); these
functions check first what it *is*, so that no model ever sees a string, a complex number or a
batch of the wrong length, and no state changes before every action of a step has passed.

The rule is Gymnasium's ``Space.contains``: an action is accepted exactly when the player's
action space's ``contains`` accepts it, with one widening for ``Box``: a numpy array of any
real dtype (bool, integer or float) is checked after its cast to the space's dtype, as
``contains`` itself casts a list (``Box(float32).contains`` refuses a float64 or int64 array
outright). So ``Discrete`` takes a Python int (``True`` is 1) or a numpy integer scalar or 0-d
array whose dtype casts safely to the space's (not ``np.uint64``, not ``np.bool_``, not a float,
not a shape-(1,) array); ``MultiBinary`` takes a numpy array, list or tuple of 0/1 values of
any dtype (bool, float 0.0/1.0 as stable-baselines3's PPO and A2C emit them, object);
``MultiDiscrete`` a numpy array, list or tuple whose dtype casts safely to the space's; ``Box``
anything ``np.asarray(action, dtype)`` turns into an array of the space's shape within its
bounds (so no NaN). :func:`check_action` is that rule for one action, and every face (the
parallel and AEC envs, the Gymnasium views, the sequential formats, the stealth envs) calls
it; :func:`check_vector_actions` is the same rule member by member for a native vector env's
batch. Both return the action's meaning (an ``int`` for ``Discrete``, float values for
``Box``, 0/1 in the space's dtype for ``MultiBinary``), so the models see one type per space;
anything refused is a ``ValueError`` naming the player, the action and the space.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces


class _Refused(Exception):
    """An action outside its space; the message says what the space takes (no player)."""


def check_action(space: spaces.Space, action: Any, who: str) -> Any:
    """The meaning of ``action`` if ``space`` contains it (module doc), else ``ValueError``.

    Args:
        space: The player's action space (``Discrete``, ``Box``, ``MultiBinary``,
            ``MultiDiscrete``; another space by its own ``contains``).
        action: One player's action.
        who: The player (``"attacker"``, ``"defender"``), for the message.

    Returns:
        ``int`` for ``Discrete``; for ``Box`` a float array of the space's shape (a float32 or
        float64 array as given, anything else as float64; a value the float32 cast puts on a
        bound is that bound); 0/1 in the space's dtype for ``MultiBinary``; int64 for
        ``MultiDiscrete``; the action itself for any other space.

    Raises:
        ValueError: Naming ``who``, the action, the space and what it takes.
    """
    try:
        return _meaning(space, action)
    except _Refused as exc:
        raise ValueError(
            f"{who} action {exc} (the action space {space}), got {_short(action)}"
        ) from None


def check_step_actions(
    actions: Any, agents: list[str], spaces_of: dict[str, spaces.Space], reset: bool, done: bool
) -> dict[str, Any]:
    """The checks a PettingZoo parallel ``step`` makes before anything changes.

    Args:
        actions: The ``{agent: action}`` dict passed to ``step``.
        agents: The live agents.
        spaces_of: Each agent's action space.
        reset: Whether ``reset`` has been called.
        done: Whether the episode has ended.

    Returns:
        ``{agent: meaning}`` (:func:`check_action`) for the live agents.

    Raises:
        RuntimeError: Before ``reset`` or after the episode ended.
        TypeError: When ``actions`` is not a dict.
        ValueError: For a missing or unknown agent's action, or an action outside its space.
    """
    if not reset:
        raise RuntimeError("step() called before reset(): call reset() first")
    if done:
        raise RuntimeError("step() called after the episode ended: call reset() to start a new one")
    if not isinstance(actions, dict):
        raise TypeError(
            f"actions must be a dict {{agent: action}} for agents {agents}, "
            f"got {type(actions).__name__}"
        )
    missing = [a for a in agents if a not in actions]
    unknown = [a for a in actions if a not in agents]
    if missing or unknown:
        raise ValueError(
            f"actions must have exactly one entry per live agent {agents}; "
            f"missing {missing}, unknown {unknown}"
        )
    return {agent: check_action(spaces_of[agent], actions[agent], agent) for agent in agents}


def _short(value: Any, limit: int = 160) -> str:
    """``repr(value)``, cut to ``limit`` characters (a long batch)."""
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


# --- one action -----------------------------------------------------------------------------


def _meaning(space: spaces.Space, action: Any) -> Any:
    """:func:`check_action` without the player: ``_Refused`` says what ``space`` takes."""
    if isinstance(space, spaces.Discrete):
        return _discrete(space, action)
    if isinstance(space, spaces.Box):
        return _box(space, action)
    if isinstance(space, spaces.MultiBinary):
        return _multibinary(space, action)
    if isinstance(space, spaces.MultiDiscrete):
        return _multidiscrete(space, action)
    try:
        ok = bool(space.contains(action))
    except Exception:  # what contains cannot read is not in the space
        ok = False
    if not ok:
        raise _Refused("must be an element of its space (space.contains(action))")
    return action


@functools.cache
def _safe_cast(source: np.dtype, target: np.dtype) -> bool:
    """``np.can_cast(source, target)`` (safe casting), as ``contains`` asks it (cached)."""
    return bool(np.can_cast(source, target))


def _discrete_rule(space: spaces.Discrete) -> str:
    return (
        f"must be an integer in [{space.start}, {space.start + space.n}): a Python int (True "
        f"is 1) or a numpy integer scalar or 0-d array whose dtype casts safely to {space.dtype}"
    )


def _discrete(space: spaces.Discrete, action: Any) -> int:
    if type(action) is int:  # the common case first
        value = action
    elif isinstance(action, int):  # bool (True is 1), IntEnum
        value = int(action)
    elif (
        isinstance(action, np.generic | np.ndarray)
        and action.shape == ()
        and action.dtype.kind in "iu"
        and _safe_cast(action.dtype, space.dtype)
    ):
        value = int(action)
    else:
        raise _Refused(_discrete_rule(space))
    if not space.start <= value < space.start + space.n:
        raise _Refused(_discrete_rule(space))
    return value


def _box(space: spaces.Box, action: Any) -> np.ndarray:
    if isinstance(action, np.ndarray):
        if action.dtype.kind not in "biuf":
            raise _Refused(
                f"must be real numbers (a bool, integer or float dtype) of shape {space.shape}, "
                f"got dtype {action.dtype}"
            )
        arr = action
    else:
        try:  # Box.contains's own cast of anything but an array
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                arr = np.asarray(action, dtype=space.dtype)
        except (TypeError, ValueError, OverflowError):
            raise _Refused(
                f"must be a numeric array of shape {space.shape} (what np.asarray(action, "
                f"{space.dtype}) reads)"
            ) from None
    if arr.shape != space.shape:
        raise _Refused(f"must have shape {space.shape}, got shape {arr.shape}")
    with np.errstate(all="ignore"):
        cast = arr.astype(space.dtype, copy=False)
        if not (bool(np.all(cast >= space.low)) and bool(np.all(cast <= space.high))):
            raise _Refused(_box_values(space, cast))
        if arr is action and arr.dtype == space.dtype:
            return arr  # within the bounds as it is
        if arr is action and arr.dtype.kind == "f":
            return _clip(space, arr)
        return _clip(space, np.asarray(action, dtype=np.float64))


def _box_values(space: spaces.Box, cast: Any) -> str:
    """Why in-shape values (cast to the space's dtype) are not in the Box."""
    if not bool(np.all(np.isfinite(cast))):
        return "must be finite (no NaN or inf)"
    return f"must lie in [{space.low.min():g}, {space.high.max():g}]"


def _clip(space: spaces.Box, values: Any) -> Any:
    """Float ``values`` on the bounds where the cast's round-off left them outside."""
    if bool(np.any(values < space.low)) or bool(np.any(values > space.high)):
        return np.clip(values, *_bounds(space))
    return values


def _bounds(space: spaces.Box) -> tuple[np.ndarray, np.ndarray]:
    return space.low.astype(np.float64), space.high.astype(np.float64)


def _as_array(action: Any) -> Any:
    """A list or tuple as ``np.array`` (as ``contains`` promotes a Sequence), else as given."""
    if isinstance(action, Sequence):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return np.array(action)
        except (TypeError, ValueError, OverflowError):
            return None
    return action


def _multibinary(space: spaces.MultiBinary, action: Any) -> np.ndarray:
    rule = f"must be a 0/1 array of shape {space.shape} (a numpy array, list or tuple; any dtype)"
    arr = _as_array(action)
    if not isinstance(arr, np.ndarray):
        raise _Refused(rule)
    if arr.shape != space.shape:
        raise _Refused(f"{rule}, got shape {arr.shape}")
    one = _zero_one(arr)
    if one is None:
        raise _Refused(rule)
    return np.asarray(one, dtype=space.dtype)


def _zero_one(arr: np.ndarray) -> np.ndarray | None:
    """``arr == 1`` where every entry is 0 or 1, else None."""
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            one = np.asarray(arr == 1)
            ok = bool(np.all(np.logical_or(arr == 0, one)))
    except Exception:  # entries that cannot be compared are not 0/1
        return None
    return one if ok else None


def _multidiscrete(space: spaces.MultiDiscrete, action: Any) -> np.ndarray:
    rule = (
        f"must be a numpy array, list or tuple of shape {space.shape} of integers (a dtype "
        f"that casts safely to {space.dtype}) with start <= action < start + nvec"
    )
    arr = _as_array(action)
    if not isinstance(arr, np.ndarray) or arr.shape != space.shape:
        raise _Refused(rule)
    if not _safe_cast(arr.dtype, space.dtype):
        raise _Refused(f"{rule}, got dtype {arr.dtype}")
    if not bool(np.all((space.start <= arr) & (arr - space.start < space.nvec))):
        raise _Refused(rule)
    return arr.astype(np.int64)


# --- a batch on numpy -----------------------------------------------------------------------


def check_batch_actions(space: spaces.Space, actions: Any, batch: int, who: str) -> np.ndarray:
    """Raise ``ValueError`` unless every member of ``actions`` is accepted by ``space``.

    A member is ``actions[i]``; it is accepted exactly when :func:`check_action` accepts it
    (``space.contains`` with the ``Box`` widening), checked at once for a numeric array. This is
    the vector env's only check of a step's actions: the models' ``batch_apply`` take the array
    it returns as valid (type, shape and range), as they do on the torch backend.

    Args:
        space: The single env's action space.
        actions: B actions: a (B, *space.shape) numeric array, or a list or tuple of B
            actions (another array-like is read by ``np.asarray``).
        batch: B, the number of members; a shorter or longer batch is an error (never
            broadcast).
        who: ``"attacker"`` or ``"defender"``, for the message.

    Returns:
        The members' meanings as one array of shape (B, *space.shape): int64 for ``Discrete``
        and ``MultiDiscrete``, the space's dtype for ``MultiBinary``, float for ``Box`` (a
        float array as given, on the bounds where round-off left it; float64 otherwise).
    """
    if (  # the common case first: a policy's integer batch for Discrete
        type(actions) is np.ndarray
        and isinstance(space, spaces.Discrete)
        and actions.shape == (batch,)
        and actions.dtype.kind in "iu"
        and _safe_cast(actions.dtype, space.dtype)
        and (not batch or (space.start <= actions.min() and actions.max() < space.start + space.n))
    ):
        return actions.astype(np.int64, copy=False)
    want = (batch, *(space.shape or ()))
    arr = actions
    if not isinstance(arr, np.ndarray | list | tuple):
        if arr is None or isinstance(arr, str | bytes):
            arr = None
        else:
            try:
                arr = np.asarray(arr)
            except Exception:  # not an array-like: refused below
                arr = None
        if arr is None:
            raise ValueError(
                f"{who} actions must be an array of shape {want} or a list of {batch} actions "
                f"of {space} (one per member), got {_short(actions)}"
            )
    if isinstance(arr, np.ndarray) and arr.dtype.kind in "biufc":
        return _batch_array(space, arr, batch, who)
    if (isinstance(arr, np.ndarray) and arr.ndim == 0) or len(arr) != batch:
        shape = np.shape(arr) if isinstance(arr, np.ndarray) else f"a sequence of {len(arr)}"
        raise ValueError(
            f"{who} actions must be an array of shape {want} (one action of {space} for each "
            f"of the {batch} members), got {shape}"
        )
    out = []
    for i, member in enumerate(arr):
        try:
            out.append(_meaning(space, member))
        except _Refused as exc:
            raise ValueError(
                f"{who} actions must each be an action of {space}; member {i} {exc}, "
                f"got {_short(member)}"
            ) from None
    return np.asarray(out, dtype=_batch_dtype(space))


def _batch_dtype(space: spaces.Space) -> Any:
    if isinstance(space, spaces.Discrete | spaces.MultiDiscrete):
        return np.int64
    if isinstance(space, spaces.MultiBinary):
        return space.dtype
    if isinstance(space, spaces.Box):
        return np.float64
    return None


def _batch_array(space: spaces.Space, arr: np.ndarray, batch: int, who: str) -> np.ndarray:
    """:func:`check_batch_actions` for a numeric array: every member's check at once."""
    want = (batch, *(space.shape or ()))
    if arr.shape != want:
        raise ValueError(
            f"{who} actions must be an array of shape {want} (one action of {space} for each "
            f"of the {batch} members), got shape {arr.shape}"
        )
    if isinstance(space, spaces.Discrete | spaces.MultiDiscrete):
        if arr.dtype.kind not in "iu" or not _safe_cast(arr.dtype, space.dtype):
            raise ValueError(
                f"{who} actions must be integers (an integer dtype that casts safely to "
                f"{space.dtype}, as for a single env) for {space}, got dtype {arr.dtype}"
            )
        if isinstance(space, spaces.Discrete):
            low, high = space.start, space.start + space.n
            allowed = f"integers in [{low}, {high})"
        else:
            low, high = space.start, space.start + space.nvec
            allowed = f"in {space}"
        if batch and (np.any(arr < low) or np.any(arr >= high)):  # the rare case: find it
            bad = ((arr < low) | (arr >= high)).reshape(batch, -1).any(axis=1)
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{who} actions must be {allowed}; member {i} has {arr[i].tolist()!r} (the "
                f"action space {space})"
            )
        return arr.astype(np.int64, copy=False)
    if isinstance(space, spaces.Box):
        if arr.dtype.kind == "c":
            raise ValueError(
                f"{who} actions must be real numbers (a bool, integer or float dtype) for "
                f"{space}, got dtype {arr.dtype}"
            )
        with np.errstate(all="ignore"):
            cast = arr.astype(space.dtype, copy=False)
            inside = ((cast >= space.low) & (cast <= space.high)).reshape(batch, -1).all(axis=1)
        if not bool(inside.all()):
            i = int(np.flatnonzero(~inside)[0])
            raise ValueError(
                f"{who} action {_box_values(space, cast[i])} (the action space {space}); "
                f"member {i} has {_short(arr[i].tolist())}"
            )
        if arr.dtype.kind != "f":
            return arr.astype(np.float64)
        return arr if arr.dtype == space.dtype else _clip(space, arr)
    if isinstance(space, spaces.MultiBinary):
        one = _zero_one(arr)
        if one is None:
            ok = np.array([_zero_one(member) is not None for member in arr])
            i = int(np.flatnonzero(~ok)[0])
            raise ValueError(
                f"{who} action must be a 0/1 array of shape {space.shape} (any dtype; {space}); "
                f"member {i} has {_short(arr[i].tolist())}"
            )
        return arr if arr.dtype == space.dtype else one.astype(space.dtype)
    out = [_meaning_or_error(space, member, i, who) for i, member in enumerate(arr)]
    return np.asarray(out)


def _meaning_or_error(space: spaces.Space, member: Any, i: int, who: str) -> Any:
    try:
        return _meaning(space, member)
    except _Refused as exc:
        raise ValueError(
            f"{who} actions must each be an action of {space}; member {i} {exc}"
        ) from None


# --- a batch on torch -----------------------------------------------------------------------


@functools.cache
def _numpy_dtype(torch_dtype: Any) -> np.dtype | None:
    """The numpy dtype of a torch dtype (None for one numpy lacks, e.g. bfloat16)."""
    import torch

    try:
        return torch.empty((), dtype=torch_dtype).numpy().dtype
    except (TypeError, RuntimeError):
        return None


def check_batch_tensor_actions(
    space: spaces.Space, actions: Any, batch: int, who: str, backend: Any
) -> Any:
    """:func:`check_batch_actions` for the torch backend: a tensor of the env's device.

    A member ``actions[i]`` is accepted exactly when its numpy counterpart is (the single
    env's rule): an integer dtype that casts safely to int64 for ``Discrete`` and
    ``MultiDiscrete`` (not ``torch.bool``, not ``torch.uint64``), 0/1 of any dtype for
    ``MultiBinary``, a real dtype (bool, integer, float) within the bounds once cast to the
    space's dtype for ``Box``.

    Args:
        space: The single env's action space.
        actions: (B, *space.shape) tensor on ``backend.device``.
        batch: B.
        who: ``"attacker"`` or ``"defender"``, for the message.
        backend: The env's torch backend (:mod:`fdia_env.backend`).

    Returns:
        The tensor as given, or its meaning where its dtype is not the models' (float64 for
        a ``Box`` tensor of a bool or integer dtype, the space's integer dtype for a complex
        ``MultiBinary`` one, a float64 ``Box`` tensor on the bounds where round-off left it).

    Raises:
        TypeError: For anything but a torch tensor, or a tensor of the wrong dtype.
        ValueError: For a tensor on another device, of the wrong shape, or with values outside
            the space.
    """
    import torch

    want = (batch, *(space.shape or ()))
    if not isinstance(actions, torch.Tensor):
        raise TypeError(
            f"{who} actions must be a torch.Tensor of shape {want} on device "
            f"{backend.device} for backend='torch' (one action of {space} per member), got "
            f"{type(actions).__module__}.{type(actions).__name__}"
        )
    if actions.device != backend.device:
        raise ValueError(
            f"{who} actions must be on the env's device {backend.device}, got a tensor on "
            f"{actions.device} (move it with .to({str(backend.device)!r}))"
        )
    dtype = actions.dtype
    if isinstance(space, spaces.Discrete | spaces.MultiDiscrete):
        np_dtype = _numpy_dtype(dtype)
        ok = np_dtype is not None and np_dtype.kind in "iu" and _safe_cast(np_dtype, space.dtype)
        allowed = f"an integer dtype that casts safely to {space.dtype} (torch.int64, ...)"
    elif isinstance(space, spaces.Box):
        ok, allowed = not dtype.is_complex, "a real dtype (bool, integer or float)"
    else:
        ok, allowed = True, "any dtype"
    if not ok:
        raise TypeError(f"{who} actions must have {allowed} for {space}, got {dtype}")
    if tuple(actions.shape) != want:
        raise ValueError(
            f"{who} actions must be a tensor of shape {want} (one action of {space} for each "
            f"of the {batch} members), got shape {tuple(actions.shape)}"
        )
    if isinstance(space, spaces.Discrete | spaces.MultiDiscrete):
        low = space.start
        high = space.start + (space.n if isinstance(space, spaces.Discrete) else space.nvec)
        bad = (actions < backend.asarray(low)) | (actions >= backend.asarray(high))
        if bool(bad.any()):
            i = int(backend.flatnonzero(bad.reshape(batch, -1).any(dim=1))[0])
            raise ValueError(
                f"{who} actions must lie in {space}; member {i} has {actions[i].tolist()!r}"
            )
        return actions
    if isinstance(space, spaces.MultiBinary):
        one = actions == 1
        bad = ~(one | (actions == 0)).reshape(batch, -1).all(dim=1)
        if bool(bad.any()):
            i = int(backend.flatnonzero(bad)[0])
            raise ValueError(
                f"{who} actions must be 0/1 for {space}; member {i} has {actions[i].tolist()!r}"
            )
        return one.to(torch.int8) if dtype.is_complex else actions
    # Box: the values cast to the space's dtype lie in the bounds
    cast_dtype = getattr(torch, np.dtype(space.dtype).name)
    cast = actions.to(cast_dtype)
    low = torch.as_tensor(space.low, device=actions.device)
    high = torch.as_tensor(space.high, device=actions.device)
    inside = ((cast >= low) & (cast <= high)).reshape(batch, -1).all(dim=1)
    if not bool(inside.all()):
        i = int(backend.flatnonzero(~inside)[0])
        reason = _box_values(space, cast[i].cpu().numpy())
        raise ValueError(
            f"{who} actions {reason.replace('must', 'must each', 1)} (the action space "
            f"{space}); member {i} has {_short(actions[i].tolist())}"
        )
    if dtype not in (torch.float32, torch.float64):
        return actions.to(torch.float64)
    if dtype == torch.float64:
        low64, high64 = (torch.as_tensor(b, device=actions.device) for b in _bounds(space))
        if bool(((actions < low64) | (actions > high64)).any()):
            return torch.clamp(actions, low64, high64)
    return actions


def check_vector_actions(
    space: spaces.Space, actions: Any, batch: int, who: str, backend: Any
) -> Any:
    """A native vector env's check of one step's actions, on the env's backend.

    Every native vector env checks its actions here and nowhere else; a batch is accepted
    exactly when each member is (the single env's rule, :func:`check_action`).

    Args:
        space: The single env's action space.
        actions: (B, *space.shape) actions: an array (or a list of B actions) on the numpy
            backend (:func:`check_batch_actions`), a tensor of the env's device on the torch
            one (:func:`check_batch_tensor_actions`).
        batch: B, the number of members.
        who: ``"attacker"`` or ``"defender"``, for the message.
        backend: The env's backend (:mod:`fdia_env.backend`).

    Returns:
        The checked actions: :func:`check_batch_actions`'s array on numpy,
        :func:`check_batch_tensor_actions`'s tensor on torch.

    Raises:
        TypeError: On torch, for anything but a tensor of an allowed dtype.
        ValueError: For actions that are not one element of ``space`` per member.
    """
    if backend.name == "numpy":
        return check_batch_actions(space, actions, batch, who)
    return check_batch_tensor_actions(space, actions, batch, who, backend)
