"""Batched covariance algebra for the exhaustive search: a 2×2 fast path and a generic one.

The search needs three operations on a batch of ``R`` filter states, in the information form of
docs/math.md §4:

- :meth:`predicted_information`: ``Y = (F P F' + Q)⁻¹`` once per parent state;
- :meth:`posterior`: ``P = (Y + J)⁻¹`` for a child that uses sensor information ``J``;
- :meth:`posterior_objective`: ``Φ((Y + J)⁻¹)`` at the last step, without forming P.

:class:`Components2` writes the 2×2 algebra out on component arrays (a state is a (3, R) array of
``[p00, p01, p11]``; a closed-form symmetric inverse), which runs an order of magnitude faster
than ``np.linalg`` on tiny matrices. :class:`MatrixAlgebra` is the generic path for any state size
(a state is an (R, n, n) array, inverses by ``np.linalg``); the tests check they agree.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from fdia_env.kalman import small
from fdia_env.kalman.linalg import sym


class CovarianceAlgebra(Protocol):
    """Operations the exhaustive search needs on batches of states."""

    def start(self, P: np.ndarray) -> np.ndarray:
        """A one-row batch holding the (n, n) covariance ``P``."""
        ...

    def rows(self, batch: np.ndarray) -> int:
        """Number of states in ``batch``."""
        ...

    def take(self, batch: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """Rows ``lo:hi`` of ``batch`` (a view)."""
        ...

    def concat(self, batches: list[np.ndarray]) -> np.ndarray:
        """Stack batches row-wise."""
        ...

    def predicted_information(self, batch: np.ndarray) -> np.ndarray:
        """``Y = (F P F' + Q)⁻¹`` for every state of ``batch``."""
        ...

    def posterior(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """``P = (Y + J)⁻¹`` for every row of ``info``; ``J`` is one (n, n) matrix."""
        ...

    def posterior_objective(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """(R,) ``Φ((Y + J)⁻¹)`` for every row of ``info``."""
        ...


def algebra_for(
    F: np.ndarray, Q: np.ndarray, objective: str, fast: bool = True
) -> CovarianceAlgebra:
    """The 2×2 component algebra for a two-component state (when ``fast``), else the generic one."""
    if fast and F.shape == (2, 2):
        return Components2(F, Q, objective)
    return MatrixAlgebra(F, Q, objective)


class Components2:
    """2×2 symmetric matrices stored as (3, R) component arrays ``[m00, m01, m11]``.

    Args:
        F: (2, 2) state transition.
        Q: (2, 2) process noise covariance.
        objective: ``"trace"`` or ``"logdet"``.
    """

    def __init__(self, F: np.ndarray, Q: np.ndarray, objective: str) -> None:
        self.F = np.asarray(F, dtype=float)
        self.Q = np.asarray(Q, dtype=float)
        self.objective = objective
        self._f = small.to_mat2(self.F)
        self._q = small.to_sym2(self.Q)

    def start(self, P: np.ndarray) -> np.ndarray:
        """A one-row batch holding ``P``."""
        return np.array([[P[0, 0]], [0.5 * (P[0, 1] + P[1, 0])], [P[1, 1]]])

    def rows(self, batch: np.ndarray) -> int:
        """Number of states."""
        return batch.shape[1]

    def take(self, batch: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """Rows ``lo:hi``."""
        return batch[:, lo:hi]

    def concat(self, batches: list[np.ndarray]) -> np.ndarray:
        """Stack row-wise."""
        return np.concatenate(batches, axis=1)

    def predicted_information(self, batch: np.ndarray) -> np.ndarray:
        """``Y = (F P F' + Q)⁻¹`` on components."""
        return np.stack(small.inv2(small.predict2(tuple(batch), self._f, self._q)))

    def posterior(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """``P = (Y + J)⁻¹`` on components."""
        y00, y01, y11 = info
        return np.stack(small.inv2((y00 + J[0, 0], y01 + J[0, 1], y11 + J[1, 1])))

    def posterior_objective(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """``tr (Y + J)⁻¹ = (a + d) / (a d − b²)`` or ``log det (Y + J)⁻¹ = −log(a d − b²)``."""
        y00, y01, y11 = info
        a = y00 + J[0, 0]
        b = y01 + J[0, 1]
        d = y11 + J[1, 1]
        det = a * d - b * b
        if self.objective == "trace":
            return (a + d) / det
        return -np.log(det)


class MatrixAlgebra:
    """Generic path: states as (R, n, n) arrays, inverses by batched ``np.linalg``.

    Args:
        F: (n, n) state transition.
        Q: (n, n) process noise covariance.
        objective: ``"trace"`` or ``"logdet"``.
    """

    def __init__(self, F: np.ndarray, Q: np.ndarray, objective: str) -> None:
        self.F = np.asarray(F, dtype=float)
        self.Q = np.asarray(Q, dtype=float)
        self.objective = objective

    def start(self, P: np.ndarray) -> np.ndarray:
        """A one-row batch holding ``P``."""
        return np.asarray(P, dtype=float)[None].copy()

    def rows(self, batch: np.ndarray) -> int:
        """Number of states."""
        return batch.shape[0]

    def take(self, batch: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """Rows ``lo:hi``."""
        return batch[lo:hi]

    def concat(self, batches: list[np.ndarray]) -> np.ndarray:
        """Stack row-wise."""
        return np.concatenate(batches, axis=0)

    def predicted_information(self, batch: np.ndarray) -> np.ndarray:
        """``Y = (F P F' + Q)⁻¹``."""
        return sym(np.linalg.inv(self.F @ batch @ self.F.T + self.Q))

    def posterior(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """``P = (Y + J)⁻¹``."""
        return sym(np.linalg.inv(info + J))

    def posterior_objective(self, info: np.ndarray, J: np.ndarray) -> np.ndarray:
        """``Φ((Y + J)⁻¹)``: trace of the inverse, or minus the log-determinant of ``Y + J``."""
        if self.objective == "trace":
            return np.trace(np.linalg.inv(info + J), axis1=-2, axis2=-1)
        sign, logdet = np.linalg.slogdet(info + J)
        return np.where(sign > 0, -logdet, np.inf)
