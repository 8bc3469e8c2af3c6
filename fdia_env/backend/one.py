"""The batch of one: the models' batched code run on one member, its batch axis dropped.

Every attack and defense model has one implementation, its ``batch_*`` methods over (B, ...)
arrays of a backend (:mod:`fdia_env.attacks.base`). The native vector envs run them on
:data:`~fdia_env.backend.NUMPY` or torch; the single env runs them on :data:`ONE`, where a (B,)
array of the batch is member 0's Python scalar and a (B, ...) array is member 0's (...) numpy
array. On Python scalars the models' per-step work costs tens of nanoseconds an operation,
where a numpy call on a one-element array costs about a microsecond (the single env steps at
tens of thousands of steps per second, so that difference is its speed).

The operations keep numpy's names and meaning with the batch axis removed: creation functions
take the batch shape and drop its first entry, a positive ``axis`` counts the batch axis (so
``sum(x, 1)`` of a (B, M) batch is ``sum(x, 0)`` of the member's (M,) row), ``take`` from a 1-D
table gives a Python scalar and from a 2-D table a new row. Indexing along the batch axis goes
through :meth:`OneBackend.col` (``x[:, None]``) and :meth:`OneBackend.member` (``x[i]``), which
every backend has.

>>> from fdia_env.backend import NUMPY, ONE
>>> import numpy as np
>>> table = np.array([5, 7, 9])
>>> NUMPY.take(table, NUMPY.full(2, 1, dtype=NUMPY.int64)).tolist(), ONE.take(table, 1)
([7, 7], 7)
>>> ONE.zeros((1, 3), dtype=ONE.int8)
array([0, 0, 0], dtype=int8)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.backend.numpy_backend import NumpyBackend

_PYTHON = {np.int64: int, np.float64: float, np.bool_: bool, None: float}
_SCALARS = frozenset({int, float, bool, np.int64, np.float64, np.bool_, np.int8, np.float32})


def _cast(value: Any, dtype: Any) -> Any:
    """``value`` as the Python scalar of ``dtype`` (float when None, as numpy's default)."""
    kind = _PYTHON.get(dtype)
    return np.asarray(value, dtype=dtype).item() if kind is None else kind(value)


def _scalar(x: Any) -> bool:
    """Whether ``x`` is one member's value of a (B,) batch (a scalar or a 0-d array)."""
    return type(x) in _SCALARS or (type(x) is np.ndarray and x.ndim == 0)


class OneBackend(NumpyBackend):
    """numpy on one batch member, whose (B,) values are Python scalars (see the module doc)."""

    name = "one"

    def __reduce__(self) -> str:
        """Pickled as a reference to :data:`ONE`: code compares backends with ``is``."""
        return "ONE"

    # --- creation: the batch shape's first entry dropped -------------------------------------
    def full(self, shape: Any, value: Any, dtype: Any = None) -> Any:
        """Member 0 of ``full(shape, value)``: a Python scalar for a (B,) shape."""
        rest = tuple(shape[1:]) if isinstance(shape, tuple | list) else ()
        return np.full(rest, value, dtype=dtype) if rest else _cast(value, dtype)

    def zeros(self, shape: Any, dtype: Any = None) -> Any:
        """Member 0 of ``zeros(shape)``."""
        rest = tuple(shape[1:]) if isinstance(shape, tuple | list) else ()
        return np.zeros(rest, dtype=dtype) if rest else _cast(0, dtype)

    def ones(self, shape: Any, dtype: Any = None) -> Any:
        """Member 0 of ``ones(shape)``."""
        rest = tuple(shape[1:]) if isinstance(shape, tuple | list) else ()
        return np.ones(rest, dtype=dtype) if rest else _cast(1, dtype)

    def empty(self, shape: Any, dtype: Any = None) -> Any:
        """Member 0 of ``empty(shape)`` (zeros: never uninitialised memory)."""
        return self.zeros(shape, dtype)

    def asarray(self, x: Any, dtype: Any = None) -> Any:
        """A table or constant: 0-d values as Python scalars, arrays as numpy arrays."""
        if _scalar(x):
            return _cast(np.asarray(x), dtype) if dtype is not None else np.asarray(x).item()
        return np.asarray(x, dtype=dtype)

    # --- elementwise, on scalars without numpy ----------------------------------------------
    def astype(self, x: Any, dtype: Any) -> Any:
        """``x`` as ``dtype``: a Python scalar for a scalar, else a numpy copy."""
        if type(x) is int and dtype is np.int64:  # the common case: a discrete action
            return x
        if _scalar(x):
            return _cast(x, dtype)
        return np.asarray(x).astype(dtype)

    def copy(self, x: Any) -> Any:
        """An independent copy (a scalar is its own)."""
        if type(x) in _SCALARS:
            return x.item() if isinstance(x, np.generic) else x
        return np.array(x)

    def where(self, cond: Any, a: Any, b: Any) -> Any:
        """``a`` where ``cond`` else ``b``."""
        if _scalar(cond):
            return a if cond else b
        return np.where(cond, a, b)

    def minimum(self, a: Any, b: Any) -> Any:
        """Elementwise minimum."""
        return min(a, b) if type(a) in _SCALARS and type(b) in _SCALARS else np.minimum(a, b)

    def maximum(self, a: Any, b: Any) -> Any:
        """Elementwise maximum."""
        return max(a, b) if type(a) in _SCALARS and type(b) in _SCALARS else np.maximum(a, b)

    def any(self, x: Any) -> bool:
        """Whether any element is true."""
        return bool(x) if _scalar(x) else bool(np.any(x))

    def all(self, x: Any) -> bool:
        """Whether every element is true."""
        return bool(x) if _scalar(x) else bool(np.all(x))

    # --- reductions and tables: the batch axis removed ----------------------------------------
    def sum(self, x: Any, axis: int) -> Any:
        """Sum over ``axis`` of the batch (so over ``axis - 1`` of the member)."""
        out = np.sum(x, axis=axis - 1 if axis > 0 else axis)
        return out.item() if out.ndim == 0 else out

    def cumsum(self, x: Any, axis: int) -> Any:
        """Cumulative sum over ``axis`` of the batch."""
        return np.cumsum(x, axis=axis - 1 if axis > 0 else axis)

    def take(self, table: Any, index: Any, axis: int = 0) -> Any:
        """``table[index]``: a Python scalar from a 1-D table, a new row from a 2-D one."""
        if type(index) is int and axis == 0:
            return table.item(index) if table.ndim == 1 else table[index].copy()
        return np.take(table, index, axis=axis)

    def flatnonzero(self, x: Any) -> Any:
        """Indices of the true members: ``[0]`` or ``[]``."""
        if _scalar(x):
            return np.arange(1 if x else 0)
        return np.flatnonzero(x)

    # --- batch-axis indexing ------------------------------------------------------------------
    def col(self, x: Any) -> Any:
        """``x[:, None]``: a (B,) batch as (B, 1); member 0's value as a one-entry list."""
        return [x]

    def member(self, x: Any, i: int) -> Any:
        """``x[i]``, member ``i`` (only 0 here)."""
        return x

    def from_members(self, values: list, dtype: Any = None) -> Any:
        """The one member's value (``values[0]``) as a Python scalar of ``dtype``."""
        return _cast(values[0], dtype)


ONE = OneBackend()
