"""Type and shape checks of actions, shared by the parallel env, the views and the vector env.

The models check what an action *means* (a bitmask within the budget, a threshold); these
functions check first what it *is*, so that no model ever sees a string, a complex number, a
bool, or a batch of the wrong length, and no state changes before every action of a step has
passed. Each failure is a ``ValueError`` that names the player and the space.

The rules are Gymnasium's ``Space.contains``, the same for one action and for a batch:
``Discrete`` and ``MultiDiscrete`` take integers only (a Python or numpy integer, or a 0-d
integer array for ``Discrete``; never a float, a bool or a shape-(1,) array), ``MultiBinary``
takes 0/1 of any real dtype (float 0.0/1.0 as stable-baselines3's PPO and A2C emit them, bool
too), ``Box`` takes finite reals within its bounds (up to float32 round-off).
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np
from gymnasium import spaces

_BOX_SLACK = 1e-6  # float32 round-off allowed outside [low, high]


def check_action(space: spaces.Space, action: Any, who: str) -> None:
    """Raise ``ValueError`` unless ``action`` is an element of ``space`` (up to round-off).

    Args:
        space: A ``Discrete``, ``Box``, ``MultiBinary`` or ``MultiDiscrete`` space.
        action: One player's action.
        who: ``"attacker"`` or ``"defender"``, for the message.
    """
    if isinstance(space, spaces.Discrete):
        index = _integer(action)
        if index is None or not space.start <= index < space.start + space.n:
            raise ValueError(
                f"{who} action must be an integer in [{space.start}, {space.start + space.n}) "
                f"(the action space {space}), got {action!r}"
            )
        return
    arr = _real_array(action, who, space)
    if arr.shape != space.shape:
        raise ValueError(
            f"{who} action must have shape {space.shape} (the action space {space}), "
            f"got shape {arr.shape}: {action!r}"
        )
    _check_values(space, arr, who)


def check_step_actions(
    actions: Any, agents: list[str], spaces_of: dict[str, spaces.Space], reset: bool, done: bool
) -> None:
    """The checks a PettingZoo parallel ``step`` makes before anything changes.

    Args:
        actions: The ``{agent: action}`` dict passed to ``step``.
        agents: The live agents.
        spaces_of: Each agent's action space.
        reset: Whether ``reset`` has been called.
        done: Whether the episode has ended.

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
    for agent in agents:
        check_action(spaces_of[agent], actions[agent], agent)


def check_batch_actions(space: spaces.Space, actions: Any, batch: int, who: str) -> np.ndarray:
    """Raise ``ValueError`` unless ``actions`` holds one element of ``space`` per member.

    This is the vector env's only check of a step's actions: the models' ``batch_apply`` take
    the array it returns as valid (type, shape and range), as they do on the torch backend.

    Args:
        space: The single env's action space.
        actions: (B, *space.shape) array (B,) for ``Discrete``.
        batch: B, the number of members; a shorter or longer batch is an error (never
            broadcast).
        who: ``"attacker"`` or ``"defender"``, for the message.

    Returns:
        The actions as a numpy array (int64 for ``Discrete`` and ``MultiDiscrete``, the given
        dtype otherwise), of shape (B, *space.shape).
    """
    if isinstance(actions, np.ndarray) and isinstance(space, spaces.Discrete):
        # the common case (a policy's integer batch), checked without the general path
        if actions.dtype.kind in "iu" and actions.shape == (batch,):
            if batch and (actions.min() < space.start or actions.max() >= space.start + space.n):
                _discrete_range_error(space, actions, who)
            return actions.astype(np.int64, copy=False)
    arr = _real_array(actions, who, space, batch=batch)
    want = (batch, *(space.shape or ()))
    if arr.shape != want:
        raise ValueError(
            f"{who} actions must be an array of shape {want} (one action of {space} for each "
            f"of the {batch} members), got shape {arr.shape}"
        )
    if isinstance(space, spaces.Discrete):
        if arr.dtype.kind not in "iu":
            raise ValueError(
                f"{who} actions must be integers (an integer dtype, as for a single env) for "
                f"{space}, got dtype {arr.dtype}"
            )
        if batch and (arr.min() < space.start or arr.max() >= space.start + space.n):
            _discrete_range_error(space, arr, who)
        return arr.astype(np.int64, copy=False)
    _check_values(space, arr, who)
    if isinstance(space, spaces.MultiDiscrete):
        return arr.astype(np.int64, copy=False)
    return arr


def _discrete_range_error(space: spaces.Discrete, arr: np.ndarray, who: str) -> None:
    """Raise the ``ValueError`` naming the first member outside ``space``."""
    bad = (arr < space.start) | (arr >= space.start + space.n)
    i = int(np.flatnonzero(bad)[0])
    raise ValueError(
        f"{who} actions must be integers in [{space.start}, {space.start + space.n}); "
        f"member {i} has {arr[i].item()!r}"
    )


def _integer(action: Any) -> int | None:
    """An integer action (Python or numpy integer, 0-d integer array), else None.

    A shape-(1,) array is not an element of ``Discrete`` (Gymnasium's ``contains`` refuses it,
    and the vector env refuses a (B, 1) batch): it is refused, not squeezed.
    """
    if type(action) is int:  # the common cases first (bool is another type)
        return action
    if type(action) is np.int64:  # a policy's sampled action
        return int(action)
    if isinstance(action, bool | np.bool_):
        return None
    if isinstance(action, numbers.Integral):
        return int(action)
    if isinstance(action, np.ndarray) and action.shape == ():
        if np.issubdtype(action.dtype, np.integer):
            return int(action)
    return None


def _real_array(action: Any, who: str, space: spaces.Space, batch: int | None = None) -> np.ndarray:
    """``action`` as a real numeric array; strings, bools, complex and objects are errors."""
    kind = "actions" if batch is not None else "action"
    shape = space.shape if batch is None else (batch, *(space.shape or ()))
    if action is None or isinstance(action, str | bytes):
        raise ValueError(
            f"{who} {kind} must be a numeric array of shape {shape} (the action space {space}), "
            f"got {action!r}"
        )
    try:
        arr = np.asarray(action)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{who} {kind} must be a numeric array for {space}, got {action!r}"
        ) from exc
    if arr.dtype == bool and not isinstance(space, spaces.MultiBinary):
        raise ValueError(f"{who} {kind} must be numeric, not boolean, for {space}, got {action!r}")
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        if arr.dtype != bool:
            raise ValueError(
                f"{who} {kind} must be real numbers for {space} (dtype int or float), "
                f"got dtype {arr.dtype}: {action!r}"
            )
    return arr


def _check_values(space: spaces.Space, arr: np.ndarray, who: str) -> None:
    if isinstance(space, spaces.Box):
        values = arr.astype(np.float64)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{who} action must be finite (no NaN or inf), got {arr.tolist()}")
        low, high = space.low.astype(np.float64), space.high.astype(np.float64)
        if np.any(values < low - _BOX_SLACK) or np.any(values > high + _BOX_SLACK):
            raise ValueError(
                f"{who} action must lie in [{space.low.min():g}, {space.high.max():g}] "
                f"(the action space {space}), got {arr.tolist()}"
            )
    elif isinstance(space, spaces.MultiBinary):
        if not np.all((arr == 0) | (arr == 1)):
            raise ValueError(
                f"{who} action must be a 0/1 array of shape {space.shape} (any real dtype; "
                f"{space}), got {arr.tolist()}"
            )
    elif isinstance(space, spaces.MultiDiscrete):
        if not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(
                f"{who} action must be integers (an integer dtype) for {space}, got dtype "
                f"{arr.dtype}: {arr.tolist()}"
            )
        if np.any(arr < space.start) or np.any(arr >= space.start + space.nvec):
            raise ValueError(f"{who} action must lie in {space}, got {arr.tolist()}")


def check_batch_tensor_actions(
    space: spaces.Space, actions: Any, batch: int, who: str, backend: Any
) -> None:
    """:func:`check_batch_actions` for the torch backend: a tensor of the env's device.

    Args:
        space: The single env's action space.
        actions: (B, *space.shape) tensor on ``backend.device``: an integer dtype for
            ``Discrete``/``MultiDiscrete``, any real dtype or bool holding 0/1 for
            ``MultiBinary``, float32 or float64 for ``Box``.
        batch: B.
        who: ``"attacker"`` or ``"defender"``, for the message.
        backend: The env's torch backend (:mod:`fdia_env.backend`).

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
    integer = not actions.dtype.is_floating_point and not actions.dtype.is_complex
    if isinstance(space, spaces.Box):
        allowed, ok = (
            "torch.float32 or torch.float64",
            actions.dtype
            in (
                torch.float32,
                torch.float64,
            ),
        )
    elif isinstance(space, spaces.MultiBinary):
        allowed, ok = "a real dtype or torch.bool", not actions.dtype.is_complex
    else:
        allowed, ok = "an integer dtype (torch.int64, ...)", integer and actions.dtype != torch.bool
    if not ok:
        raise TypeError(f"{who} actions must have {allowed} for {space}, got {actions.dtype}")
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
    elif isinstance(space, spaces.MultiBinary):
        if actions.dtype != torch.bool and bool(((actions != 0) & (actions != 1)).any()):
            raise ValueError(f"{who} actions must be 0/1 for {space}")
    else:
        if not bool(torch.isfinite(actions).all()):
            raise ValueError(f"{who} actions must be finite (no NaN or inf)")
        low = backend.asarray(space.low.astype(np.float64)) - _BOX_SLACK
        high = backend.asarray(space.high.astype(np.float64)) + _BOX_SLACK
        values = actions.to(torch.float64)
        if bool(((values < low) | (values > high)).any()):
            raise ValueError(
                f"{who} actions must lie in [{space.low.min():g}, {space.high.max():g}] "
                f"(the action space {space})"
            )


def check_vector_actions(
    space: spaces.Space, actions: Any, batch: int, who: str, backend: Any
) -> Any:
    """A native vector env's check of one step's actions, on the env's backend.

    Every native vector env checks its actions here and nowhere else.

    Args:
        space: The single env's action space.
        actions: (B, *space.shape) actions: an array on the numpy backend
            (:func:`check_batch_actions`), a tensor of the env's device on the torch one
            (:func:`check_batch_tensor_actions`).
        batch: B, the number of members.
        who: ``"attacker"`` or ``"defender"``, for the message.
        backend: The env's backend (:mod:`fdia_env.backend`).

    Returns:
        The checked actions: :func:`check_batch_actions`'s array on numpy, the tensor as given
        on torch.

    Raises:
        TypeError: On torch, for anything but a tensor of an allowed dtype.
        ValueError: For actions that are not one element of ``space`` per member.
    """
    if backend.name == "numpy":
        return check_batch_actions(space, actions, batch, who)
    check_batch_tensor_actions(space, actions, batch, who, backend)
    return actions
