"""Shared attack histories: the 2-state expected covariance of a batch as a table of nodes.

In expected dynamics the filter's covariance after k steps depends only on the sensor subsets
used so far (docs/math.md §1): members with the same history share one covariance. A
:class:`HistoryTable` keeps every history the batch has reached as a node (its covariance, its
observation features and its Φ) and each member as a node index; a step looks up the child
``(node, used)`` in a transition table and computes only the children never reached before.
Once a batch has explored the histories its attacks reach (a budget bounds them), a step costs a
few gathers of B indices instead of the closed-form update and the features of B members.

A node is computed with the single environment's own kernel, operation for operation
(:func:`fdia_env.kalman.small.predict2`, :func:`~fdia_env.kalman.small.info_update2`,
:func:`~fdia_env.kalman.small.shape_features2` and the objective, applied elementwise to the
new nodes, with numpy's logarithm as the single env's): the native vector env's members
therefore equal the single env bit for bit while the table holds them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fdia_env.kalman import small

# total bytes of the transition table (nodes × 2**M int32) before the engine stops sharing
MAX_TABLE_BYTES = 2**25
MAX_NODES = 2**20


class HistoryTable:
    """Nodes of the histories of a batch of 2-state filters in expected dynamics.

    Args:
        start: (a, b, d) components of the covariance at the window start (node 0).
        f: (f11, f12, f21, f22) of F.
        q: (a, b, d) components of Q.
        j: ``j[u]`` the (a, b, d) components of ``Σ_{i in u} J_i`` for each bitmask u < 2**M.
        objective: ``"trace"`` or ``"logdet"``.

    Attributes:
        size: Nodes computed so far.
        max_nodes: The most nodes the table holds (its transition table within
            ``MAX_TABLE_BYTES``).
    """

    def __init__(
        self,
        start: small.Sym2,
        f: small.Mat2,
        q: small.Sym2,
        j: Sequence[small.Sym2],
        objective: str,
    ) -> None:
        self._f, self._q, self._scale = f, q, start
        self._j = np.array(j, dtype=np.float64).T  # (3, 2**M)
        self._A = len(j)
        self._shift = self._A.bit_length() - 1
        self._objective = objective
        self.max_nodes = min(MAX_NODES, MAX_TABLE_BYTES // (4 * self._A))
        self.size = 0
        self._cap = 0
        self._grow(256)
        self._add(np.array([start], dtype=np.float64).T)

    # --- storage --------------------------------------------------------------------------------
    def _grow(self, need: int) -> None:
        cap = max(need, 2 * self._cap)
        n = self.size

        def grown(old: np.ndarray | None, shape: tuple, dtype, fill) -> np.ndarray:
            new = np.full(shape, fill, dtype=dtype)
            if old is not None:
                new[..., :n] = old[..., :n]
            return new

        old = self._cap > 0
        self.comps = grown(self.comps if old else None, (3, cap), np.float64, 0.0)
        self.feats64 = grown(self.feats64 if old else None, (3, cap), np.float64, 0.0)
        self.feats = grown(self.feats if old else None, (3, cap), np.float32, 0.0)
        self.phi = grown(self.phi if old else None, (cap,), np.float64, 0.0)
        child = np.full((cap, self._A), -1, dtype=np.int32)
        if old:
            child[:n] = self._child.reshape(self._cap, self._A)[:n]
        self._child = child.reshape(-1)
        self._cap = cap

    def _add(self, comps: np.ndarray) -> np.ndarray:
        """Append nodes of the (3, U) covariance components; returns their indices."""
        U = comps.shape[1]
        if self.size + U > self._cap:
            self._grow(self.size + U)
        ids = np.arange(self.size, self.size + U)
        self.comps[:, ids] = comps
        a, b, d = comps
        # small.shape_features2 and the objective, elementwise (the same numpy logarithm)
        lv1 = np.minimum(np.maximum(np.log(a / self._scale[0]), -30.0), 30.0)
        lv2 = np.minimum(np.maximum(np.log(d / self._scale[2]), -30.0), 30.0)
        corr = np.minimum(np.maximum(small.corr2(a, b, d), -1.0), 1.0)
        self.feats64[:, ids] = np.stack([lv1, lv2, corr])
        self.feats[:, ids] = self.feats64[:, ids]
        self.phi[ids] = a + d if self._objective == "trace" else small.logdet2((a, b, d))
        self.size += U
        return ids

    # --- step -------------------------------------------------------------------------------------
    def fits(self, count: int) -> bool:
        """Whether ``count`` more nodes fit."""
        return self.size + count <= self.max_nodes

    def step(self, node: np.ndarray, used: np.ndarray) -> np.ndarray | None:
        """(B,) int32 child nodes of the (B,) int32 ``node`` under the (B,) ``used`` bitmasks.

        Returns:
            The children, or None when the new ones would not fit (the table is unchanged).
        """
        key = np.left_shift(node, self._shift)
        np.bitwise_or(key, used, out=key, casting="unsafe")
        child = self._child.take(key)
        if len(child) and child.min() < 0:
            new = np.unique(key[child < 0])
            if not self.fits(len(new)):
                return None
            parent, u = new >> self._shift, new & (self._A - 1)
            comps = _kernel(self.comps[:, parent], self._f, self._q, self._j[:, u])
            self._child[new] = self._add(comps)
            child = self._child.take(key)
        return child


def _kernel(p: np.ndarray, f: small.Mat2, q: small.Sym2, j: np.ndarray) -> np.ndarray:
    """``info_update2(predict2(p, f, q), j)`` on (3, U) components, operation for operation."""
    pred = small.predict2((p[0], p[1], p[2]), f, q)
    post = small.info_update2(pred, (j[0], j[1], j[2]))
    return np.stack(post)
