"""The attacker's c2-maximising bias covariance: lives in :mod:`fdia_env.detection.attack`.

The detection game builds its default attacker from it, and the environments cannot depend on
the baselines, so the implementation is in the core package; this module re-exports it.
"""

from fdia_env.detection.attack import c2_gain_matrix, c2_optimal_pbb

__all__ = ["c2_gain_matrix", "c2_optimal_pbb"]
