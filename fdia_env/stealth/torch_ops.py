"""torch versions of the stealth envs' non-elementary functions (imported only for torch).

:func:`ncx2_sf` is the non-central χ² tail ``P[χ²_k(λ) > x]`` on a tensor of non-centralities,
as the Poisson mixture ``1 − Σ_j Pois(j; λ/2) P(k/2 + j, x/2)`` (P the regularised lower
incomplete gamma function), summed over a window of j around λ/2 wide enough that the Poisson
mass left out is below 1e-30. P at the window's first j comes from its power series (in log
space), the others from the recurrence ``P(a + 1, y) = P(a, y) − y^a e^{−y} / Γ(a + 1)``:
``torch.special.gammaincc`` itself is off by up to 3e-10 where a ≈ y > 20, which the
numpy backend's scipy is not. It agrees with scipy's ``stats.ncx2.sf`` to about 1e-14 absolute
(the test compares them over λ in [0, 7e3]). On the CPU :func:`ncx2_sf` calls scipy itself on
the tensors' memory (the numpy backend's own figures), since the series is hundreds of times
slower than scipy on the tails of IEEE 118's test (λ up to 6e3); other devices run the series.

>>> import torch
>>> from scipy import stats
>>> lam = torch.tensor([0.5, 20.0, 300.0], dtype=torch.float64)
>>> got = ncx2_sf(30.0, 21, lam)
>>> want = stats.ncx2.sf(30.0, 21, lam.numpy())
>>> bool(torch.all((got - torch.as_tensor(want)).abs() < 1e-12))
True
"""

from __future__ import annotations

import math
from typing import Any

import torch

from fdia_env.stealth.tails import certain
from fdia_env.stealth.tails import ncx2_sf as numpy_ncx2_sf

_CHUNK = 1 << 22
"""Largest number of (member, term) pairs evaluated at once (32 MiB of float64)."""


def ncx2_sf(x: Any, dof: Any, lam: torch.Tensor) -> torch.Tensor:
    """``P[χ²_dof(λ) > x]`` for every entry of ``lam`` (float64, any device).

    On the CPU this is scipy's ``stats.ncx2.sf`` (as the numpy backend computes it); on other
    devices the Poisson series of :func:`ncx2_sf_series` (see the module docstring).

    Args:
        x: The threshold, > 0: a float, or an (N,) tensor (one per entry of ``lam``).
        dof: Degrees of freedom, >= 1: an int, or an (N,) tensor.
        lam: (N,) non-centralities >= 0.

    Returns:
        (N,) float64 tail probabilities in [0, 1].
    """
    lam = lam.to(torch.float64)
    x = torch.as_tensor(x, dtype=torch.float64, device=lam.device).expand_as(lam)
    dof = torch.as_tensor(dof, dtype=torch.float64, device=lam.device).expand_as(lam)
    out = torch.ones_like(lam)  # 1.0 exactly far in the tail (fdia_env.stealth.tails)
    rest = torch.nonzero(~certain(x, dof, lam)).flatten()
    if rest.numel() == 0:
        return out
    if lam.device.type != "cpu":
        out[rest] = ncx2_sf_series(x[rest], dof[rest], lam[rest])
        return out
    out[rest] = torch.as_tensor(
        numpy_ncx2_sf(x[rest].numpy(), dof[rest].numpy(), lam[rest].detach().numpy()),
        dtype=torch.float64,
    )
    return out


def ncx2_sf_series(x: Any, dof: Any, lam: torch.Tensor) -> torch.Tensor:
    """:func:`ncx2_sf` by the Poisson series in torch on ``lam``'s device (module docstring)."""
    lam = lam.to(torch.float64)
    out = torch.empty_like(lam)
    if lam.numel() == 0:
        return out
    x = torch.as_tensor(x, dtype=torch.float64, device=lam.device).expand_as(lam)
    dof = torch.as_tensor(dof, dtype=torch.float64, device=lam.device).expand_as(lam)
    mu = 0.5 * lam
    # Poisson(μ) mass beyond 12 standard deviations + 30 from its mean is below 1e-30
    width = math.ceil(12.0 * math.sqrt(float(mu.max())) + 30.0)
    j = torch.arange(2 * width + 1, dtype=torch.float64, device=lam.device)
    # the series of P(a, y) = y^a e^{-y} / Γ(a + 1) · Σ_n y^n / ((a + 1) ... (a + n))
    y_max = 0.5 * float(x.max())
    n = torch.arange(1, math.ceil(y_max + 20.0 * math.sqrt(y_max) + 60.0), dtype=torch.float64)
    n = n.to(lam.device)
    rows = max(1, _CHUNK // max(j.numel(), n.numel()))
    for start in range(0, lam.numel(), rows):
        part = slice(start, start + rows)
        m, y, half_k = mu[part, None], 0.5 * x[part, None], 0.5 * dof[part, None]
        log_y = torch.log(y)
        first = torch.clamp(torch.floor(m) - width, min=0.0)  # (rows, 1) the window's first j
        a0 = half_k + first
        log_series = torch.logsumexp(
            torch.cat(
                [torch.zeros_like(a0), n * log_y - torch.cumsum(torch.log(a0 + n), dim=1)], dim=1
            ),
            dim=1,
            keepdim=True,
        )
        p0 = torch.exp(a0 * log_y - y - torch.lgamma(a0 + 1.0) + log_series)
        a = a0 + j  # (rows, J)
        drop = torch.exp(a * log_y - y - torch.lgamma(a + 1.0))  # P(a, y) − P(a + 1, y)
        lower = torch.clamp(p0 - (torch.cumsum(drop, dim=1) - drop), min=0.0)  # P(a, y)
        terms = first + j
        weights = torch.exp(torch.xlogy(terms, m) - m - torch.lgamma(terms + 1.0))
        out[part] = 1.0 - torch.sum(weights * lower, dim=1)
    return torch.clamp(out, 0.0, 1.0)
