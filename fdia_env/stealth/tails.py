"""The non-central χ² tail ``P[χ²_k(λ) > x]`` at every non-centrality, numpy or torch.

scipy's ``stats.ncx2.sf`` returns NaN above a non-centrality of about 1e19 (and the Poisson
series of :mod:`fdia_env.stealth.torch_ops` would need ~sqrt(λ) terms). Far out it is not
needed: by Laurent & Massart (2000, Lemma 8), ``P[χ²_k(λ) ≤ k + λ − 2 sqrt((k + 2λ) t)] ≤
e^{−t}``; with ``t = 750`` the miss probability is below the smallest double, so wherever
``k + λ − x ≥ 2 sqrt(750 (k + 2λ))`` (:func:`certain`) the tail is 1.0 exactly, as it is for
an infinite λ.

>>> import numpy as np
>>> ncx2_sf(12.6, 6, np.array([0.0, 10.0, 1e19, 1e300])).round(6).tolist()
[0.049846, 0.643357, 1.0, 1.0]
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

_LOG_TINY = 750.0
"""``t`` with ``e^{−t}`` below the smallest positive double (``e^{−745}``)."""


def certain(x: Any, dof: Any, lam: Any) -> Any:
    """Where ``P[χ²_dof(λ) > x]`` is 1.0 in float64 (numpy arrays or torch tensors).

    Args:
        x: The threshold (scalar or broadcastable to ``lam``).
        dof: Degrees of freedom (scalar or broadcastable to ``lam``).
        lam: Non-centralities >= 0 (inf allowed).

    Returns:
        Boolean array or tensor of ``lam``'s shape.
    """
    return dof + lam - x >= 2.0 * ((dof + 2.0 * lam) * _LOG_TINY) ** 0.5


def ncx2_sf(x: Any, dof: Any, lam: Any) -> np.ndarray:
    """``P[χ²_dof(λ) > x]`` on numpy: scipy's ``stats.ncx2.sf``, 1.0 where :func:`certain`.

    Args:
        x: The threshold > 0 (scalar or array broadcastable to ``lam``).
        dof: Degrees of freedom >= 1 (scalar or array broadcastable to ``lam``).
        lam: Non-centralities >= 0 (inf allowed).

    Returns:
        float64 array of the broadcast shape, in [0, 1].
    """
    x, dof, lam = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, dof, lam)))
    with np.errstate(over="ignore", invalid="ignore"):
        sure = certain(x, dof, lam)
    out = np.ones(lam.shape)
    rest = ~sure
    if np.any(rest):
        out[rest] = stats.ncx2.sf(x[rest], dof[rest], lam[rest])
    return np.clip(out, 0.0, 1.0)
