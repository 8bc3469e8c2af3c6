"""Array backends: one namespace of the array operations the simulation engine needs.

The engine (:mod:`fdia_env.envs.engine`) and the Kalman primitives it calls are written
once against a :class:`~fdia_env.backend.base.Backend`; :data:`NUMPY` runs them on numpy arrays,
:func:`get_backend` ``("torch", device)`` on torch tensors of one device (CPU or CUDA). torch is
imported only when a torch backend is asked for, so numpy users never pay its import.

>>> from fdia_env.backend import NUMPY, namespace
>>> import numpy as np
>>> namespace(np.zeros(2)) is NUMPY
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.backend.base import Backend
from fdia_env.backend.numpy_backend import NUMPY
from fdia_env.backend.one import ONE

BACKENDS = ("numpy", "torch")


def get_backend(name: str = "numpy", device: Any = None) -> Backend:
    """The backend ``name`` on ``device``.

    Args:
        name: ``"numpy"`` or ``"torch"``.
        device: numpy: None or ``"cpu"``; torch: a ``torch.device`` or its string (``"cpu"``,
            ``"cuda"``, ``"cuda:1"``); None means ``"cpu"``.

    Raises:
        ValueError: For another name, a device numpy cannot use, a malformed device, or a CUDA
            device when torch has no usable GPU (or no such GPU index).
    """
    if not isinstance(name, str) or name not in BACKENDS:
        raise ValueError(f"backend must be one of {list(BACKENDS)}, got {name!r}")
    if name == "numpy":
        if not (device is None or (isinstance(device, str) and device == "cpu")):
            raise ValueError(
                f"device must be None or 'cpu' for backend='numpy' (numpy runs on the CPU; use "
                f"backend='torch' for another device), got {device!r}"
            )
        return NUMPY
    from fdia_env.backend.torch_backend import torch_backend

    return torch_backend(device)


def is_torch(x: Any) -> bool:
    """Whether ``x`` is a torch tensor (without importing torch)."""
    return type(x).__module__.startswith("torch")


def namespace(x: Any) -> Backend:
    """The backend of an array: :data:`NUMPY` for numpy arrays, torch on the tensor's device."""
    if type(x) is np.ndarray:  # the common case first, without a further call
        return NUMPY
    if is_torch(x):
        return get_backend("torch", x.device)
    return NUMPY


__all__ = ["BACKENDS", "NUMPY", "ONE", "Backend", "get_backend", "is_torch", "namespace"]
