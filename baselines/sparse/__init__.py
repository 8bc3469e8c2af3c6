"""Sparse attacks under perfect detection (docs/math.md §4): solvers and their policies.

Every solver is ``f(system_or_scenario, budget, horizon, objective="trace") -> SparseResult``:

- :func:`exhaustive` (EXS): the optimum, by a batched frontier search over all ``C(M·N, c)`` sets;
- :func:`sfs`, :func:`sbs`, :func:`sfs_ss`: greedy forward / backward selection and SFS with swaps;
- :func:`dp`: dynamic programming over (budget spent, step); exact for a scalar state;
- :func:`branch_and_bound`: the optimum with a proof (or, under a time limit, a certified gap)
  beyond enumeration; :func:`upper_bound` is its provable bound.

``result.policy()`` plays the answer in ``sparse_attack_v0``.

>>> from baselines.sparse import sfs
>>> result = sfs("ch4-position", budget=5, horizon=6)
>>> round(result.value, 4)
0.0328
"""

from baselines.sparse.bnb import branch_and_bound
from baselines.sparse.dp import dp
from baselines.sparse.exhaustive import exhaustive
from baselines.sparse.greedy import sbs, sfs, sfs_ss
from baselines.sparse.policy import SparsePolicy
from baselines.sparse.problem import SparseProblem, make_problem
from baselines.sparse.result import SparseResult
from baselines.sparse.split import upper_bound

SOLVERS = {"exs": exhaustive, "sfs": sfs, "sbs": sbs, "sfs_ss": sfs_ss, "dp": dp}

__all__ = [
    "SOLVERS",
    "SparsePolicy",
    "SparseProblem",
    "SparseResult",
    "branch_and_bound",
    "dp",
    "exhaustive",
    "make_problem",
    "sbs",
    "sfs",
    "sfs_ss",
    "upper_bound",
]
