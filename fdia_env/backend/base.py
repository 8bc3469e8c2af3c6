"""The backend interface: exactly the array operations the simulation engine uses.

Names and semantics follow numpy (``axis``, ``out``, broadcasting); arithmetic, ``@``,
comparisons, bit operations and indexing are the arrays' own operators, shared by numpy and
torch. Every function takes and returns arrays of the backend (on its device); ``any``/``all``
return Python bools (on a GPU that is a synchronisation point).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

# the largest |e| of Backend.unit_scale: 2**±1020 and its reciprocal are normal floats
UNIT_EXPONENT = 1020


class Backend(ABC):
    """An array namespace: numpy, or torch on one device.

    Attributes:
        name: ``"numpy"`` or ``"torch"``.
        device: The device arrays are created on (``"cpu"`` for numpy).
        float64, float32, int64, int8, bool: The dtypes of this backend.
    """

    name: str
    device: Any
    float64: Any
    float32: Any
    int64: Any
    int8: Any
    bool: Any

    # --- creation -------------------------------------------------------------------------
    @abstractmethod
    def asarray(self, x: Any, dtype: Any = None) -> Any:
        """``x`` (array, list, scalar) as an array of this backend and device."""

    @abstractmethod
    def zeros(self, shape: Any, dtype: Any = None) -> Any:
        """Zeros (float64 unless ``dtype``)."""

    @abstractmethod
    def ones(self, shape: Any, dtype: Any = None) -> Any:
        """Ones (float64 unless ``dtype``)."""

    @abstractmethod
    def full(self, shape: Any, value: Any, dtype: Any = None) -> Any:
        """An array filled with ``value``."""

    @abstractmethod
    def empty(self, shape: Any, dtype: Any = None) -> Any:
        """Uninitialised (float64 unless ``dtype``)."""

    @abstractmethod
    def arange(self, n: int) -> Any:
        """``[0, n)`` as int64."""

    @abstractmethod
    def eye(self, n: int) -> Any:
        """(n, n) float64 identity."""

    @abstractmethod
    def copy(self, x: Any) -> Any:
        """An independent copy."""

    @abstractmethod
    def astype(self, x: Any, dtype: Any) -> Any:
        """``x`` converted to ``dtype`` (a copy)."""

    @abstractmethod
    def broadcast_to(self, x: Any, shape: Any) -> Any:
        """A writable copy of ``x`` broadcast to ``shape``."""

    @abstractmethod
    def to_numpy(self, x: Any) -> np.ndarray:
        """``x`` as a numpy array on the host."""

    # --- elementwise and reductions -------------------------------------------------------
    @abstractmethod
    def where(self, cond: Any, a: Any, b: Any) -> Any:
        """``a`` where ``cond`` else ``b`` (broadcasting; scalars allowed)."""

    @abstractmethod
    def minimum(self, a: Any, b: Any) -> Any:
        """Elementwise minimum (``b`` may be a scalar)."""

    @abstractmethod
    def maximum(self, a: Any, b: Any) -> Any:
        """Elementwise maximum (``b`` may be a scalar)."""

    @abstractmethod
    def clip(self, x: Any, low: float, high: float) -> Any:
        """``x`` clipped to [low, high]."""

    @abstractmethod
    def clip_(self, x: Any, bound: float) -> Any:
        """``x`` clipped to [−bound, bound] in place."""

    @abstractmethod
    def log(self, x: Any) -> Any:
        """Natural logarithm."""

    @abstractmethod
    def log_into(self, x: Any, out: Any) -> None:
        """``out[...] = log(x)``, numpy computing it in ``out``'s precision.

        float32 for the rows of an observation, float64 for the single env's features.
        """

    @abstractmethod
    def sqrt(self, x: Any) -> Any:
        """Square root."""

    @abstractmethod
    def isfinite(self, x: Any) -> Any:
        """Elementwise finiteness."""

    @abstractmethod
    def multiply(self, a: Any, b: Any, out: Any = None) -> Any:
        """``a * b``, into ``out`` when given."""

    @abstractmethod
    def divide(self, a: Any, b: Any, out: Any = None) -> Any:
        """``a / b``, into ``out`` when given (its dtype may be narrower)."""

    @abstractmethod
    def empty_like(self, x: Any) -> Any:
        """Uninitialised, like ``x``."""

    @abstractmethod
    def any(self, x: Any) -> bool:
        """Whether any element is true (a Python bool)."""

    @abstractmethod
    def all(self, x: Any) -> bool:
        """Whether every element is true (a Python bool)."""

    @abstractmethod
    def sum(self, x: Any, axis: int) -> Any:
        """Sum over ``axis``."""

    @abstractmethod
    def cumsum(self, x: Any, axis: int) -> Any:
        """Cumulative sum over ``axis``."""

    @abstractmethod
    def stack(self, arrays: Any, axis: int = 0) -> Any:
        """Stack equally shaped arrays along a new ``axis``."""

    @abstractmethod
    def take(self, table: Any, index: Any, axis: int = 0) -> Any:
        """``table`` indexed by the integer array ``index`` along ``axis``."""

    @abstractmethod
    def flatnonzero(self, x: Any) -> Any:
        """Indices of the true / non-zero elements of a 1-D array."""

    @abstractmethod
    def unique(self, x: Any) -> Any:
        """Sorted distinct values."""

    # --- linear algebra (leading batch dimensions) ------------------------------------------
    @abstractmethod
    def einsum(self, spec: str, *operands: Any) -> Any:
        """Einstein summation."""

    def rows_times(self, a: Any, m: Any) -> Any:
        """``a @ m`` for (B, w) rows ``a`` and a (w, n) matrix ``m``: (B, n).

        numpy computes it one row at a time (a stacked product), so that a row's result does
        not depend on B: one (B, w) @ (w, n) product is a BLAS gemm (gemv at B = 1) whose
        rounding of a row depends on the number of rows. torch: one product.
        """
        return a @ m

    @abstractmethod
    def diagonal(self, a: Any) -> Any:
        """Diagonals of the last two axes, (..., n)."""

    @abstractmethod
    def trace(self, a: Any) -> Any:
        """Traces over the last two axes."""

    @abstractmethod
    def solve(self, a: Any, b: Any) -> Any:
        """``a⁻¹ b`` for (..., n, n) ``a`` and (..., n, k) ``b``."""

    @abstractmethod
    def inv(self, a: Any) -> Any:
        """Matrix inverses."""

    @abstractmethod
    def eigh(self, a: Any) -> tuple[Any, Any]:
        """Eigenvalues (ascending) and eigenvectors of symmetric matrices."""

    @abstractmethod
    def slogdet(self, a: Any) -> tuple[Any, Any]:
        """Sign and log of the absolute determinant."""

    @abstractmethod
    def cholesky(self, a: Any) -> Any:
        """Lower Cholesky factors of symmetric positive definite matrices."""

    @abstractmethod
    def cholesky_solve(self, factor: Any, b: Any) -> Any:
        """``(L L')⁻¹ b`` from the lower factor ``L``."""

    @abstractmethod
    def flip_last2(self, a: Any) -> Any:
        """``a[..., ::-1, ::-1]``."""

    @abstractmethod
    def unit_scale(self, m: Any) -> tuple[Any, Any]:
        """Powers of two ``c = 2**-e`` that put ``c·m`` in [0.5, 1) (``e`` clamped to ±1020).

        Returns ``(c, e)``, both float64. Multiplying by ``c`` is exact (no rounding) for every
        normal result, so a formula evaluated on ``c``-scaled inputs rounds exactly as the
        unscaled one wherever that one neither overflows nor underflows.
        """

    # --- randomness -----------------------------------------------------------------------
    @abstractmethod
    def generator(self, seed: int | None) -> Any:
        """A random generator of this backend and device (seeded from entropy when None)."""

    @abstractmethod
    def normal(self, generator: Any, shape: Any) -> Any:
        """Standard normal float64 draws."""

    @abstractmethod
    def uniform(self, generator: Any, shape: Any) -> Any:
        """Uniform float64 draws in [0, 1)."""

    @abstractmethod
    def searchsorted(self, sorted_values: Any, values: Any) -> Any:
        """Insertion indices to the right of equal values (numpy's ``side="right"``)."""

    # --- batch-axis indexing (the batch of one, fdia_env.backend.one, drops that axis) ------
    def col(self, x: Any) -> Any:
        """``x[:, None]``: a (B,) batch as (B, 1)."""
        return x[:, None]

    def member(self, x: Any, i: int) -> Any:
        """``x[i]``: member ``i`` of a batch."""
        return x[i]

    def from_members(self, values: list, dtype: Any = None) -> Any:
        """A (B,) batch from the B members' Python values."""
        return self.asarray(values, dtype=dtype)

    def __repr__(self) -> str:
        return f"Backend({self.name!r}, device={str(self.device)!r})"
