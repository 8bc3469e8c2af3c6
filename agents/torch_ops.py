"""The operations torch-ppo writes itself: log-probabilities and entropies, and tanh on the CPU.

- :func:`masked_categorical`: ``log π(a)`` and the entropy of ``softmax`` over the legal actions,
  as one fused autograd function. The illegal logits are replaced by the dtype's minimum
  (``torch.where(mask, logits, finfo.min)``), the log-softmax is taken once, and the backward pass
  is the closed form ``∂ log π(a)/∂z = e_a − p``, ``∂H/∂z = −p ⊙ (log p + H)``: no per-call
  ``Categorical``, no ``exp`` of the masked entries (on the CPU ``exp`` of a value below -88 takes
  a slow path, ten times and more the normal cost: ``p`` comes from ``softmax``, whose own
  exponential has none), and exactly zero gradient on an illegal logit (the backward pass
  multiplies by ``p`` and ``p log p``, both 0 there, never by ``log p``, the dtype's minimum, which
  ``Categorical``'s own backward multiplies by the incoming gradient and overflows to NaN once that
  exceeds 1). Equal to ``torch.distributions.Categorical`` over the masked logits to round-off
  (``tests/test_torch_ops.py``).
- :func:`normal_log_prob` and :func:`normal_entropy`: the diagonal Gaussian's, summed over the
  action dimensions, written as ``torch.distributions.Normal`` computes them (same operations,
  same results bit for bit) without building one.
- :func:`gumbel_max`: a draw from ``softmax(z)`` by Gumbel-max with a given generator.
- :class:`Tanh`: ``nn.Tanh`` whose CPU forward is NumPy's ``tanh`` (float32 and float64; other
  devices and dtypes: ``torch.tanh``) and whose backward is torch's ``tanh_backward``. torch's own
  CPU kernel is correctly rounded (0.5 ulp) but costs about 4 ns an element, as much as the
  layer's matrix product for these 64-wide layers; NumPy's SIMD ``tanh`` is within 1.4 ulp
  (measured on 10⁵ points over ±10³⁰) and four to six times faster. The values are those of
  ``torch.tanh`` to round-off (``tests/test_torch_ops.py``).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))
_ENTROPY_CONST = 0.5 + 0.5 * math.log(2 * math.pi)


def mask_logits(logits: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """``logits`` with the illegal entries (``mask`` False) set to the dtype's minimum.

    ``mask`` None: every action is legal (``logits`` itself is returned).
    """
    if mask is None:
        return logits
    return torch.where(mask, logits, torch.finfo(logits.dtype).min)


class _MaskedCategorical(torch.autograd.Function):
    """(log π(action), entropy) of softmax over the legal logits, with a closed-form backward."""

    @staticmethod
    def forward(ctx, logits, mask, action):
        z = mask_logits(logits, mask)
        logp_all = torch.log_softmax(z, -1)
        p = torch.softmax(z, -1)  # its own exp: 0 on an illegal action, no slow path
        plogp = p * logp_all  # 0 · finfo.min = 0 on an illegal action
        entropy = -plogp.sum(-1)
        index = action.long().unsqueeze(-1)
        ctx.save_for_backward(p, plogp, entropy, index)
        return logp_all.gather(-1, index).squeeze(-1), entropy

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_logp, grad_entropy):
        p, plogp, entropy, index = ctx.saved_tensors
        # dH/dz = -(p log p + p H), d log p_a/dz = e_a - p: with g, h the incoming gradients
        # of H and log p_a, -g p log p - p (g H + h) + h e_a (no log p itself: an illegal
        # entry, p = 0 and p log p = 0, gets exactly 0 whatever g is)
        g, h = grad_entropy.unsqueeze(-1), grad_logp.unsqueeze(-1)
        grad = p * (g * entropy.unsqueeze(-1) + h).neg_()
        grad.addcmul_(plogp, g, value=-1.0)
        grad.scatter_add_(-1, index, h)
        return grad, None, None


def masked_categorical(
    logits: torch.Tensor, action: torch.Tensor, mask: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Log-probability of ``action`` and entropy of the categorical policy over legal actions.

    Args:
        logits: (N, A) unnormalised log-probabilities.
        action: (N,) action indices (each legal where ``mask`` is given).
        mask: (N, A) booleans, True for a legal action; None: all legal.

    Returns:
        ``(log_prob, entropy)``, each (N,): ``log softmax(z)[action]`` and
        ``-Σ_legal p log p`` with ``z = torch.where(mask, logits, finfo.min)``. Both are
        differentiable in ``logits``; an illegal logit gets gradient 0.
    """
    return _MaskedCategorical.apply(logits, mask, action)


def categorical_log_prob(z: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """``log softmax(z)[action]``, (N,), for already masked logits ``z`` (no entropy)."""
    return torch.log_softmax(z, -1).gather(-1, action.long().unsqueeze(-1)).squeeze(-1)


def gumbel_max(z: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    """One draw per row from ``softmax(z)`` (Gumbel-max; a masked logit is never drawn)."""
    u = torch.rand(z.shape, generator=generator, device=z.device, dtype=z.dtype)
    gumbel = -torch.log(-torch.log(u.clamp_min(1e-20)))
    return (z + gumbel).argmax(-1)


def normal_log_prob(mean: torch.Tensor, std: torch.Tensor, value: torch.Tensor) -> torch.Tensor:
    """Log-density of ``value`` under the diagonal Gaussian, summed over the last dimension.

    The operations of ``torch.distributions.Normal(mean, std).log_prob(value).sum(-1)``.
    """
    var = std**2
    return (-((value - mean) ** 2) / (2 * var) - std.log() - _LOG_SQRT_2PI).sum(-1)


def normal_entropy(std: torch.Tensor) -> torch.Tensor:
    """Entropy of the diagonal Gaussian, summed over the last dimension (as ``Normal``'s)."""
    return (_ENTROPY_CONST + torch.log(std)).sum(-1)


def _tanh(x: torch.Tensor) -> torch.Tensor:
    """``tanh(x)``: NumPy's on a CPU float32/float64 tensor (no copy in or out), else torch's."""
    if x.device.type != "cpu" or x.dtype not in (torch.float32, torch.float64):
        return torch.tanh(x)
    x = x.detach().contiguous()
    out = torch.empty_like(x)
    np.tanh(x.numpy(), out=out.numpy())
    return out


class _Tanh(torch.autograd.Function):
    """tanh with torch's backward ``g (1 − y²)`` from the saved output."""

    @staticmethod
    def forward(ctx, x):
        y = _tanh(x)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad):
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


class Tanh(nn.Module):
    """``nn.Tanh`` with NumPy's forward on the CPU (see the module docstring); no state."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``tanh(x)`` elementwise, differentiable."""
        if torch.is_grad_enabled() and x.requires_grad:
            return _Tanh.apply(x)
        return _tanh(x)
