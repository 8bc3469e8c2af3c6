"""Closed-form kernels for 2-state filters (the tracking model), one formula per function.

A symmetric 2×2 matrix ``[[a, b], [b, d]]`` is the tuple ``(a, b, d)``. The components may be
plain Python floats (one environment: several times faster than numpy calls on 2×2 arrays,
whose per-call overhead dominates) or equally shaped numpy arrays (a batch stored as component
arrays, as the exhaustive search does). :func:`predict2`, :func:`inv2`, :func:`info_update2`,
:func:`trace2`, :func:`logdet2` and :func:`corr2` work on both (numpy arrays or torch tensors);
the batched numpy functions in :mod:`fdia_env.kalman.filter` are the reference they are tested
against.

Scale: the products ``a d`` and ``b²`` leave float64 for covariances beyond about 1e±154 (a
system whose Q, R and P0 are all scaled by 1e200 or 1e-200). Where such a product is not a
normal float, :func:`inv2`, :func:`logdet2` and :func:`corr2` evaluate the same formula on the
components scaled by a power of two (exact) and scale the result back; everywhere else they run
the plain formula, so a float and an array member take the same IEEE operations in both cases
and the results in the normal range are those of the plain formula, bit for bit.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fdia_env.backend import namespace
from fdia_env.backend.base import UNIT_EXPONENT

Sym2 = tuple[float, float, float]
Mat2 = tuple[float, float, float, float]

_TINY = float(np.finfo(np.float64).tiny)  # 2**-1022: the smallest normal float
_HUGE = float(np.finfo(np.float64).max)
_LN2 = math.log(2.0)


def _unit_scale(m: float) -> tuple[float, float]:
    """:meth:`~fdia_env.backend.base.Backend.unit_scale` of one float: ``(2**-e, e)``."""
    e = min(max(math.frexp(m)[1], -UNIT_EXPONENT), UNIT_EXPONENT)
    return math.ldexp(1.0, -e), float(e)


def to_sym2(P: np.ndarray) -> Sym2:
    """``[[a, b], [b, d]] -> (a, b, d)`` (the symmetric part's upper triangle)."""
    return (float(P[0, 0]), 0.5 * float(P[0, 1] + P[1, 0]), float(P[1, 1]))


def from_sym2(p: Sym2) -> np.ndarray:
    """``(a, b, d) -> [[a, b], [b, d]]``."""
    a, b, d = p
    return np.array([[a, b], [b, d]])


def to_mat2(F: np.ndarray) -> Mat2:
    """``[[f11, f12], [f21, f22]] -> (f11, f12, f21, f22)``."""
    return (float(F[0, 0]), float(F[0, 1]), float(F[1, 0]), float(F[1, 1]))


def predict2(p: Sym2, f: Mat2, q: Sym2) -> Sym2:
    """``P[k+1|k] = F P F' + Q``."""
    a, b, d = p
    f11, f12, f21, f22 = f
    x11, x12 = f11 * a + f12 * b, f11 * b + f12 * d  # first row of F P
    x21, x22 = f21 * a + f22 * b, f21 * b + f22 * d  # second row of F P
    return (
        x11 * f11 + x12 * f12 + q[0],
        x11 * f21 + x12 * f22 + q[1],
        x21 * f21 + x22 * f22 + q[2],
    )


def inv2(p: Sym2) -> Sym2:
    """``[[a, b], [b, d]]⁻¹ = [[d, −b], [−b, a]] / (a d − b²)``.

    Where ``a d − b²`` is not a normal float (covariances beyond about 1e±154), the formula
    runs on ``c·(a, b, d)`` with ``c = 2**-e`` putting ``max(|a|, |d|)`` in [0.5, 1), and the
    inverse is ``c`` times that one's.
    """
    a, b, d = p
    det = a * d - b * b
    if isinstance(det, float):
        if _TINY <= det <= _HUGE:
            return (d / det, -b / det, a / det)
        return _inv2_scaled(a, b, d, _unit_scale(max(abs(a), abs(d)))[0])
    xp = namespace(det)
    ok = (det >= _TINY) & (det <= _HUGE)
    if xp.all(ok):
        return (d / det, -b / det, a / det)
    with np.errstate(all="ignore"):
        scaled = _inv2_scaled(a, b, d, xp.unit_scale(xp.maximum(abs(a), abs(d)))[0])
        plain = (d / det, -b / det, a / det)
        return tuple(xp.where(ok, x, y) for x, y in zip(plain, scaled, strict=True))


def _inv2_scaled(a: Any, b: Any, d: Any, c: Any) -> Sym2:
    """:func:`inv2` of ``c·(a, b, d)``, times ``c``: the inverse, for a power of two ``c``."""
    a, b, d = a * c, b * c, d * c
    det = a * d - b * b
    return (d / det * c, -b / det * c, a / det * c)


def info_update2(p_pred: Sym2, j: Sym2) -> Sym2:
    """``P[k|k] = (P[k|k−1]⁻¹ + J)⁻¹`` with ``J = Σ_used H_i' R_i⁻¹ H_i``."""
    i = inv2(p_pred)
    return inv2((i[0] + j[0], i[1] + j[1], i[2] + j[2]))


def trace2(p: Sym2) -> float:
    """``tr P``."""
    return p[0] + p[2]


def logdet2(p: Sym2) -> Any:
    """``log det P`` (−inf if P is singular), of floats or of component arrays.

    Where ``det = a d − b²`` is not a normal float, ``log det(c P) − 2 log c`` with the power of
    two ``c`` of :func:`inv2` (``2 e log 2`` added exactly as it is written here, so a float and
    an array member agree).

    The logarithms here are numpy's (not :func:`math.log`, which differs in the last bit for a
    few arguments): the batched engine takes them of whole arrays, and a member must equal the
    single env's float kernel bit for bit.
    """
    a, b, d = p
    det = a * d - b * b
    if isinstance(det, float):
        if _TINY <= det <= _HUGE:
            return float(np.log(det))
        c, e = _unit_scale(max(abs(a), abs(d)))
        det = (a * c) * (d * c) - (b * c) * (b * c)
        return float(np.log(det)) + (2.0 * e) * _LN2 if det > 0 else -math.inf
    xp = namespace(det)
    ok = (det >= _TINY) & (det <= _HUGE)
    if xp.all(ok):
        return xp.log(det)
    with np.errstate(all="ignore"):
        c, e = xp.unit_scale(xp.maximum(abs(a), abs(d)))
        scaled = (a * c) * (d * c) - (b * c) * (b * c)
        scaled = xp.where(scaled > 0, xp.log(scaled) + (2.0 * e) * _LN2, -math.inf)
        return xp.where(ok, xp.log(det), scaled)


def corr2(a: Any, b: Any, d: Any) -> Any:
    """The correlation ``b / sqrt(a d)`` of floats or arrays (not clipped).

    Where ``a d`` is not a normal float (variances beyond about 1e±154), ``b / (sqrt(a)
    sqrt(d))`` instead; both square roots are IEEE's, so a float and an array member agree.
    """
    prod = a * d
    if isinstance(prod, float):
        if _TINY <= prod <= _HUGE:
            return b / math.sqrt(prod)
        return b / (math.sqrt(a) * math.sqrt(d))
    xp = namespace(prod)
    ok = (prod >= _TINY) & (prod <= _HUGE)
    if xp.all(ok):
        return b / xp.sqrt(prod)
    with np.errstate(all="ignore"):
        return b / xp.where(ok, xp.sqrt(prod), xp.sqrt(a) * xp.sqrt(d))


def shape_features2(p: Sym2, scale: Sym2) -> list[float]:
    """``[log(a / a0), log(d / d0), b / sqrt(a d)]``, clipped to [−30, 30] and [−1, 1]."""
    a, b, d = p
    lv1 = min(max(float(np.log(a / scale[0])), -30.0), 30.0)
    lv2 = min(max(float(np.log(d / scale[2])), -30.0), 30.0)
    return [lv1, lv2, min(max(corr2(a, b, d), -1.0), 1.0)]


# --- stacked components: a batch as one (3, B) array [a; b; d] -----------------------------


def predict_matrix2(f: Mat2) -> np.ndarray:
    """The 3×3 matrix C with ``vech(F P F') = C vech(P)`` for ``vech(P) = [a, b, d]``.

    ``F P F'`` is linear in (a, b, d): its entries are
    ``f11² a + 2 f11 f12 b + f12² d``, ``f11 f21 a + (f11 f22 + f12 f21) b + f12 f22 d`` and
    ``f21² a + 2 f21 f22 b + f22² d``, so a whole batch predicts with one matrix product.
    """
    f11, f12, f21, f22 = f
    return np.array([
        [f11 * f11, 2.0 * f11 * f12, f12 * f12],
        [f11 * f21, f11 * f22 + f12 * f21, f12 * f22],
        [f21 * f21, 2.0 * f21 * f22, f22 * f22],
    ])  # fmt: skip


def predict2_stacked(comp: np.ndarray, C: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``P[k+1|k] = F P F' + Q`` for (3, B) components: ``C comp + q`` (numpy or torch)."""
    out = C @ comp
    out += q[:, None]
    return out


def inv2_stacked(comp: np.ndarray) -> np.ndarray:
    """``[[a, b], [b, d]]⁻¹ = [[d, −b], [−b, a]] / (a d − b²)`` for (3, B) components.

    ``comp`` may be a numpy array or a torch tensor (:mod:`fdia_env.backend`).
    """
    xp = namespace(comp)
    a, b, d = comp
    inv_det = 1.0 / (a * d - b * b)
    out = xp.empty_like(comp)
    xp.multiply(d, inv_det, out=out[0])
    xp.multiply(b, inv_det, out=out[1])
    out[1] *= -1.0
    xp.multiply(a, inv_det, out=out[2])
    return out
