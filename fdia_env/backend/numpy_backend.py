"""The numpy backend: the engine's operations as the numpy functions themselves.

Most attributes are numpy's own functions, bound at construction, so that a call through the
backend costs what the direct numpy call costs (no wrapper frame).
"""

from __future__ import annotations

import operator
from typing import Any

import numpy as np

from fdia_env.backend.base import UNIT_EXPONENT, Backend


class NumpyBackend(Backend):
    """numpy on the CPU (float64 unless told otherwise)."""

    name = "numpy"
    device = "cpu"
    float64 = np.float64
    float32 = np.float32
    int64 = np.int64
    int8 = np.int8
    bool = np.bool_

    # numpy's functions, bound as plain attributes (no wrapper frame)
    asarray = staticmethod(np.asarray)
    zeros = staticmethod(np.zeros)
    ones = staticmethod(np.ones)
    full = staticmethod(np.full)
    empty = staticmethod(np.empty)
    eye = staticmethod(np.eye)
    where = staticmethod(np.where)
    minimum = staticmethod(np.minimum)
    maximum = staticmethod(np.maximum)
    clip = staticmethod(np.clip)
    log = staticmethod(np.log)
    sqrt = staticmethod(np.sqrt)
    isfinite = staticmethod(np.isfinite)
    multiply = staticmethod(np.multiply)
    empty_like = staticmethod(np.empty_like)
    cumsum = staticmethod(np.cumsum)
    stack = staticmethod(np.stack)
    take = staticmethod(np.ndarray.take)  # the method: np.take adds two Python frames
    flatnonzero = staticmethod(np.flatnonzero)
    unique = staticmethod(np.unique)
    einsum = staticmethod(np.einsum)
    solve = staticmethod(np.linalg.solve)
    inv = staticmethod(np.linalg.inv)
    eigh = staticmethod(np.linalg.eigh)
    slogdet = staticmethod(np.linalg.slogdet)
    cholesky = staticmethod(np.linalg.cholesky)
    # C-level callables, no Python frame: ``copy(x)`` is ``x.copy()`` (an independent copy)
    copy = staticmethod(operator.methodcaller("copy"))

    def __reduce__(self) -> str:
        """Pickled as a reference to :data:`NUMPY`: code compares backends with ``is``."""
        return "NUMPY"

    def rows_times(self, a: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Row by row (see :meth:`Backend.rows_times`): a member equals the batch of one."""
        return np.matmul(a[:, None, :], m)[:, 0, :]

    def arange(self, n: int) -> np.ndarray:
        """``[0, n)`` as int64."""
        return np.arange(n, dtype=np.int64)

    def astype(self, x: Any, dtype: Any) -> np.ndarray:
        """``x`` converted to ``dtype`` (a copy)."""
        return np.asarray(x).astype(dtype)

    def broadcast_to(self, x: Any, shape: Any) -> np.ndarray:
        """A writable copy of ``x`` broadcast to ``shape``."""
        return np.broadcast_to(x, shape).copy()

    def to_numpy(self, x: Any) -> np.ndarray:
        """``x`` itself as a numpy array."""
        return np.asarray(x)

    def clip_(self, x: np.ndarray, bound: float) -> np.ndarray:
        """``x`` clipped to [−bound, bound] in place (np.clip's wrapper costs more here)."""
        np.minimum(x, bound, out=x)
        np.maximum(x, -bound, out=x)
        return x

    def log_into(self, x: np.ndarray, out: np.ndarray) -> None:
        """``out[...] = log(x)`` computed in ``out``'s precision (float32 for an observation)."""
        np.log(x, dtype=out.dtype, out=out)

    def divide(self, a: Any, b: Any, out: Any = None) -> np.ndarray:
        """``a / b``, into ``out`` (a narrower float dtype allowed) when given."""
        if out is None:
            return np.divide(a, b)
        return np.divide(a, b, out=out, casting="same_kind")

    def any(self, x: np.ndarray) -> bool:
        """Whether any element is true (the method: np.any's dispatch costs more)."""
        return bool(x.any())

    def all(self, x: np.ndarray) -> bool:
        """Whether every element is true."""
        return bool(x.all())

    def sum(self, x: Any, axis: int) -> np.ndarray:
        """Sum over ``axis``."""
        return np.sum(x, axis=axis)

    def diagonal(self, a: np.ndarray) -> np.ndarray:
        """Diagonals of the last two axes."""
        return np.diagonal(a, axis1=-2, axis2=-1)

    def trace(self, a: np.ndarray) -> np.ndarray:
        """Traces over the last two axes."""
        return np.trace(a, axis1=-2, axis2=-1)

    def cholesky_solve(self, factor: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``(L L')⁻¹ b`` by two solves (numpy has no triangular batched solve)."""
        y = np.linalg.solve(factor, b)
        return np.linalg.solve(np.swapaxes(factor, -1, -2), y)

    def flip_last2(self, a: np.ndarray) -> np.ndarray:
        """``a[..., ::-1, ::-1]`` (a view)."""
        return a[..., ::-1, ::-1]

    def unit_scale(self, m: Any) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`Backend.unit_scale`."""
        e = np.clip(np.frexp(m)[1], -UNIT_EXPONENT, UNIT_EXPONENT)
        return np.ldexp(1.0, -e), e.astype(np.float64)

    def generator(self, seed: int | None) -> np.random.Generator:
        """``np.random.default_rng(seed)``."""
        return np.random.default_rng(seed)

    def normal(self, generator: np.random.Generator, shape: Any) -> np.ndarray:
        """Standard normal draws."""
        return generator.standard_normal(shape)

    def uniform(self, generator: np.random.Generator, shape: Any) -> np.ndarray:
        """Uniform draws in [0, 1)."""
        return generator.random(shape)

    def searchsorted(self, sorted_values: np.ndarray, values: Any) -> np.ndarray:
        """``np.searchsorted(sorted_values, values, side="right")``."""
        return np.searchsorted(sorted_values, values, side="right")


NUMPY = NumpyBackend()
"""The numpy backend (a singleton: compare with ``is``)."""
