"""The torch backend: the engine's operations on tensors of one device (CPU or CUDA).

Everything is float64 unless told otherwise (the engine's expected dynamics must equal the numpy
backend's to 1e-10). Random draws come from a ``torch.Generator`` on the device.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from fdia_env.backend.base import UNIT_EXPONENT, Backend

_DEVICE_TYPES = ("cpu", "cuda")


def check_device(device: Any) -> torch.device:
    """``device`` as a ``torch.device`` with an explicit CUDA index.

    Raises:
        ValueError: For a malformed device, a type other than cpu/cuda, or a CUDA device when
            torch sees no GPU (or not that many).
    """
    if device is None:
        return torch.device("cpu")
    if not isinstance(device, str | torch.device):
        raise ValueError(
            f"device must be a torch.device or a string such as 'cpu', 'cuda' or 'cuda:0', "
            f"got {device!r}"
        )
    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(
            f"device must be 'cpu', 'cuda' or 'cuda:<index>', got {device!r} ({exc})"
        ) from exc
    if dev.type not in _DEVICE_TYPES:
        raise ValueError(f"device must be a cpu or cuda device, got {device!r}")
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(
                f"device={device!r} needs a CUDA GPU, but torch.cuda.is_available() is False "
                f"(torch {torch.__version__}); use device='cpu'"
            )
        count = torch.cuda.device_count()
        index = torch.cuda.current_device() if dev.index is None else dev.index
        if not 0 <= index < count:
            raise ValueError(
                f"device={device!r}: no such GPU, torch sees {count} (cuda:0..cuda:{count - 1})"
            )
        dev = torch.device("cuda", index)
    return dev


_NUMPY_DTYPES = {
    np.dtype(np.float64): torch.float64,
    np.dtype(np.float32): torch.float32,
    np.dtype(np.int64): torch.int64,
    np.dtype(np.int8): torch.int8,
    np.dtype(np.bool_): torch.bool,
}


def _shape(shape: Any) -> tuple[int, ...]:
    """The ``shape`` argument of numpy (an int or a tuple) as a tuple for torch."""
    return (int(shape),) if isinstance(shape, int | np.integer) else tuple(shape)


class TorchBackend(Backend):
    """torch tensors on ``device`` (float64 unless told otherwise)."""

    name = "torch"
    float64 = torch.float64
    float32 = torch.float32
    int64 = torch.int64
    int8 = torch.int8
    bool = torch.bool

    where = staticmethod(torch.where)
    log = staticmethod(torch.log)
    sqrt = staticmethod(torch.sqrt)
    isfinite = staticmethod(torch.isfinite)
    empty_like = staticmethod(torch.empty_like)
    einsum = staticmethod(torch.einsum)
    solve = staticmethod(torch.linalg.solve)
    inv = staticmethod(torch.linalg.inv)
    eigh = staticmethod(torch.linalg.eigh)
    slogdet = staticmethod(torch.linalg.slogdet)
    cholesky = staticmethod(torch.linalg.cholesky)
    cholesky_solve = staticmethod(torch.cholesky_solve)

    def __init__(self, device: torch.device) -> None:
        self.device = device

    def __reduce__(self) -> tuple:
        """Unpickled through :func:`torch_backend` (one instance per device)."""
        return torch_backend, (str(self.device),)

    def _dtype(self, dtype: Any, default: Any = torch.float64) -> Any:
        if dtype is None:
            return default
        if isinstance(dtype, torch.dtype):
            return dtype
        return _NUMPY_DTYPES[np.dtype(dtype)]

    def asarray(self, x: Any, dtype: Any = None) -> torch.Tensor:
        """``x`` as a tensor on the device (numpy arrays keep their dtype unless told)."""
        if isinstance(x, np.ndarray):
            if not x.flags.writeable:  # read-only system matrices: torch wants its own copy
                x = x.copy()
            if dtype is None:
                return torch.as_tensor(x, dtype=self._dtype(x.dtype), device=self.device)
        if dtype is None:
            return torch.as_tensor(x, device=self.device)
        return torch.as_tensor(x, dtype=self._dtype(dtype), device=self.device)

    def zeros(self, shape: Any, dtype: Any = None) -> torch.Tensor:
        """Zeros (float64 unless ``dtype``)."""
        return torch.zeros(_shape(shape), dtype=self._dtype(dtype), device=self.device)

    def ones(self, shape: Any, dtype: Any = None) -> torch.Tensor:
        """Ones (float64 unless ``dtype``)."""
        return torch.ones(_shape(shape), dtype=self._dtype(dtype), device=self.device)

    def full(self, shape: Any, value: Any, dtype: Any = None) -> torch.Tensor:
        """A tensor filled with ``value`` (dtype inferred from it unless given)."""
        if dtype is None:
            dtype = (
                torch.bool
                if isinstance(value, bool)
                else torch.int64
                if isinstance(value, int)
                else torch.float64
            )
        return torch.full(_shape(shape), value, dtype=self._dtype(dtype), device=self.device)

    def empty(self, shape: Any, dtype: Any = None) -> torch.Tensor:
        """Uninitialised (float64 unless ``dtype``)."""
        return torch.empty(_shape(shape), dtype=self._dtype(dtype), device=self.device)

    def arange(self, n: int) -> torch.Tensor:
        """``[0, n)`` as int64."""
        return torch.arange(n, dtype=torch.int64, device=self.device)

    def eye(self, n: int) -> torch.Tensor:
        """(n, n) float64 identity."""
        return torch.eye(n, dtype=torch.float64, device=self.device)

    def copy(self, x: torch.Tensor) -> torch.Tensor:
        """An independent copy."""
        return x.clone()

    def astype(self, x: torch.Tensor, dtype: Any) -> torch.Tensor:
        """``x`` converted to ``dtype`` (a copy)."""
        return x.to(self._dtype(dtype), copy=True)

    def broadcast_to(self, x: Any, shape: Any) -> torch.Tensor:
        """A writable copy of ``x`` broadcast to ``shape``."""
        return self.asarray(x).expand(*shape).clone()

    def to_numpy(self, x: torch.Tensor) -> np.ndarray:
        """``x`` copied to the host as numpy."""
        return x.detach().cpu().numpy()

    def minimum(self, a: torch.Tensor, b: Any) -> torch.Tensor:
        """Elementwise minimum (``b`` may be a scalar)."""
        return torch.clamp(a, max=b) if isinstance(b, int | float) else torch.minimum(a, b)

    def maximum(self, a: torch.Tensor, b: Any) -> torch.Tensor:
        """Elementwise maximum (``b`` may be a scalar)."""
        return torch.clamp(a, min=b) if isinstance(b, int | float) else torch.maximum(a, b)

    def clip(self, x: torch.Tensor, low: float, high: float) -> torch.Tensor:
        """``x`` clipped to [low, high]."""
        return torch.clamp(x, low, high)

    def clip_(self, x: torch.Tensor, bound: float) -> torch.Tensor:
        """``x`` clipped to [−bound, bound] in place."""
        return x.clamp_(-bound, bound)

    def log_into(self, x: torch.Tensor, out: torch.Tensor) -> None:
        """``out[...] = log(x)`` (computed in x's precision, stored in out's)."""
        out.copy_(torch.log(x))

    def multiply(self, a: Any, b: Any, out: Any = None) -> torch.Tensor:
        """``a * b``, into ``out`` when given."""
        if out is None:
            return torch.mul(a, b)
        return torch.mul(a, b, out=out)

    def divide(self, a: Any, b: Any, out: Any = None) -> torch.Tensor:
        """``a / b``, into ``out`` (its dtype may be narrower) when given."""
        if out is None:
            return torch.div(a, b)
        out.copy_(torch.div(a, b))
        return out

    def any(self, x: torch.Tensor) -> bool:
        """Whether any element is true (synchronises with the device)."""
        return bool(x.any())

    def all(self, x: torch.Tensor) -> bool:
        """Whether every element is true (synchronises with the device)."""
        return bool(x.all())

    def sum(self, x: torch.Tensor, axis: int) -> torch.Tensor:
        """Sum over ``axis``."""
        return x.sum(dim=axis)

    def cumsum(self, x: torch.Tensor, axis: int) -> torch.Tensor:
        """Cumulative sum over ``axis``."""
        return torch.cumsum(x, dim=axis)

    def stack(self, arrays: Any, axis: int = 0) -> torch.Tensor:
        """Stack along a new ``axis``."""
        return torch.stack(list(arrays), dim=axis)

    def take(self, table: torch.Tensor, index: torch.Tensor, axis: int = 0) -> torch.Tensor:
        """``table`` indexed by ``index`` along ``axis``."""
        if index.ndim == 1:
            return torch.index_select(table, axis, index)
        return table[(slice(None),) * axis + (index,)]

    def flatnonzero(self, x: torch.Tensor) -> torch.Tensor:
        """Indices of the true / non-zero elements."""
        return torch.nonzero(x.reshape(-1), as_tuple=True)[0]

    def unique(self, x: torch.Tensor) -> torch.Tensor:
        """Sorted distinct values."""
        return torch.unique(x, sorted=True)

    def diagonal(self, a: torch.Tensor) -> torch.Tensor:
        """Diagonals of the last two axes."""
        return torch.diagonal(a, dim1=-2, dim2=-1)

    def trace(self, a: torch.Tensor) -> torch.Tensor:
        """Traces over the last two axes."""
        return torch.diagonal(a, dim1=-2, dim2=-1).sum(-1)

    def flip_last2(self, a: torch.Tensor) -> torch.Tensor:
        """``a[..., ::-1, ::-1]`` (a copy: torch has no negative strides)."""
        return torch.flip(a, (-2, -1))

    def unit_scale(self, m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """See :meth:`Backend.unit_scale`."""
        e = torch.frexp(m).exponent.clamp(-UNIT_EXPONENT, UNIT_EXPONENT)
        return torch.ldexp(torch.ones_like(m), -e), e.to(torch.float64)

    def generator(self, seed: int | None) -> torch.Generator:
        """A ``torch.Generator`` on the device, seeded (from entropy when None)."""
        gen = torch.Generator(device=self.device)
        if seed is None:
            gen.seed()
        else:
            gen.manual_seed(int(seed))
        return gen

    def normal(self, generator: torch.Generator, shape: Any) -> torch.Tensor:
        """Standard normal float64 draws on the device."""
        return torch.randn(
            _shape(shape), generator=generator, dtype=torch.float64, device=self.device
        )

    def uniform(self, generator: torch.Generator, shape: Any) -> torch.Tensor:
        """Uniform float64 draws in [0, 1) on the device."""
        return torch.rand(
            _shape(shape), generator=generator, dtype=torch.float64, device=self.device
        )

    def searchsorted(self, sorted_values: Any, values: torch.Tensor) -> torch.Tensor:
        """Numpy's ``searchsorted(..., side="right")``."""
        return torch.searchsorted(self.asarray(sorted_values), values, right=True)


_INSTANCES: dict[str, TorchBackend] = {}


def torch_backend(device: Any = None) -> TorchBackend:
    """The one :class:`TorchBackend` of ``device`` (checked by :func:`check_device`)."""
    dev = check_device(device)
    key = str(dev)
    if key not in _INSTANCES:
        _INSTANCES[key] = TorchBackend(dev)
    return _INSTANCES[key]
