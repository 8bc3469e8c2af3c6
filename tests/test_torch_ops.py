"""torch-ppo's fused log-probabilities and entropies against torch.distributions."""

from __future__ import annotations

import pytest
import torch
from torch.distributions import Categorical, Normal

from agents.torch_ops import (
    Tanh,
    categorical_log_prob,
    gumbel_max,
    mask_logits,
    masked_categorical,
    normal_entropy,
    normal_log_prob,
)


def _case(seed: int, n: int = 64, a: int = 37, dtype=torch.float32, scale: float = 3.0):
    """Random logits, masks with at least one legal action per row, legal actions."""
    g = torch.Generator().manual_seed(seed)
    logits = (torch.randn(n, a, generator=g) * scale).to(dtype)
    mask = torch.rand(n, a, generator=g) < 0.6
    mask[torch.arange(n), torch.randint(a, (n,), generator=g)] = True
    action = torch.multinomial(mask.double(), 1, generator=g).squeeze(-1)
    return logits, mask, action


def _reference(logits, mask, action):
    """``Categorical`` over the logits with the illegal ones at the dtype's minimum."""
    dist = Categorical(logits=torch.where(mask, logits, torch.finfo(logits.dtype).min))
    return dist.log_prob(action), dist.entropy()


@pytest.mark.parametrize("seed", range(5))
def test_masked_log_prob_and_entropy_equal_categoricals(seed):
    logits, mask, action = _case(seed)
    logp, entropy = masked_categorical(logits, action, mask)
    ref_logp, ref_entropy = _reference(logits, mask, action)
    torch.testing.assert_close(logp, ref_logp, rtol=0, atol=1e-6)
    torch.testing.assert_close(entropy, ref_entropy, rtol=0, atol=1e-6)


def test_float64_values_and_gradients_equal_autograd_through_categorical():
    logits, mask, action = _case(7, dtype=torch.float64)
    # a loss of both outputs; weights below 1: Categorical's own backward multiplies the
    # dtype's minimum (an illegal logit) by them and overflows to NaN above
    weights = torch.rand(2, logits.shape[0], dtype=torch.float64) * 1.8 - 0.9
    x = logits.clone().requires_grad_()
    logp, entropy = masked_categorical(x, action, mask)
    (weights[0] @ logp + weights[1] @ entropy).backward()
    y = logits.clone().requires_grad_()
    ref_logp, ref_entropy = _reference(y, mask, action)
    (weights[0] @ ref_logp + weights[1] @ ref_entropy).backward()
    torch.testing.assert_close(logp, ref_logp, rtol=0, atol=1e-12)
    torch.testing.assert_close(entropy, ref_entropy, rtol=0, atol=1e-12)
    torch.testing.assert_close(x.grad, y.grad, rtol=0, atol=1e-12)
    assert (x.grad[~mask] == 0).all()  # an illegal logit is not pushed anywhere


def test_the_closed_form_backward_passes_gradcheck():
    logits, mask, action = _case(3, n=6, a=9, dtype=torch.float64)
    x = logits.clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda v: masked_categorical(v, action, mask), (x,))
    assert torch.autograd.gradcheck(lambda v: masked_categorical(v, action, None), (x,))


def test_no_mask_is_the_all_legal_mask():
    logits, _, action = _case(11)
    everything = torch.ones_like(logits, dtype=torch.bool)
    for a, b in zip(
        masked_categorical(logits, action, None),
        masked_categorical(logits, action, everything),
        strict=True,
    ):
        assert torch.equal(a, b)


def test_a_large_loss_weight_keeps_the_gradient_finite():
    """The masked entries' log p is the dtype's minimum: their terms must not overflow."""
    logits, mask, action = _case(5)
    x = logits.clone().requires_grad_()
    logp, entropy = masked_categorical(x, action, mask)
    (1e6 * entropy.sum() + 1e6 * logp.sum()).backward()
    assert torch.isfinite(x.grad).all() and (x.grad[~mask] == 0).all()


def test_a_near_deterministic_policy_has_entropy_zero_not_nan():
    logits = torch.tensor([[0.0, -500.0, -1e30], [80.0, -80.0, 0.0]])
    mask = torch.tensor([[True, True, False], [True, True, True]])
    logp, entropy = masked_categorical(logits, torch.tensor([0, 0]), mask)
    ref_logp, ref_entropy = _reference(logits, mask, torch.tensor([0, 0]))
    torch.testing.assert_close(entropy, ref_entropy, rtol=0, atol=1e-6)
    torch.testing.assert_close(logp, ref_logp, rtol=0, atol=1e-6)


def test_rollout_log_prob_is_the_update_log_prob():
    logits, mask, action = _case(2)
    z = mask_logits(logits, mask)
    assert torch.equal(categorical_log_prob(z, action), masked_categorical(logits, action, mask)[0])


def test_gumbel_max_never_draws_an_illegal_action_and_follows_the_softmax():
    logits = torch.tensor([1.0, 0.0, 5.0, -1.0]).expand(200_000, 4)
    mask = torch.tensor([True, True, False, True]).expand(200_000, 4)
    draws = gumbel_max(mask_logits(logits, mask), torch.Generator().manual_seed(0))
    freq = torch.bincount(draws, minlength=4).double() / draws.numel()
    p = torch.softmax(torch.tensor([1.0, 0.0, float("-inf"), -1.0], dtype=torch.float64), 0)
    assert freq[2] == 0
    torch.testing.assert_close(freq, p, rtol=0, atol=5e-3)  # 200k draws: std <= 1.2e-3


@pytest.mark.parametrize("seed", range(3))
def test_normal_log_prob_and_entropy_are_torch_distributions_bit_for_bit(seed):
    g = torch.Generator().manual_seed(seed)
    mean = torch.randn(128, 10, generator=g)
    std = (torch.randn(10, generator=g) * 0.3 - 0.5).exp().expand_as(mean)
    value = mean + std * torch.randn(128, 10, generator=g)
    dist = Normal(mean, std, validate_args=False)
    assert torch.equal(normal_log_prob(mean, std, value), dist.log_prob(value).sum(-1))
    assert torch.equal(normal_entropy(std), dist.entropy().sum(-1))


def _ulps(y: torch.Tensor, exact: torch.Tensor) -> float:
    """The largest error of float32 ``y`` in units in the last place of the exact value."""
    e = exact.float()
    ulp = (torch.nextafter(e.abs(), torch.tensor(float("inf"))) - e.abs()).double()
    return float(((y.double() - exact).abs() / ulp).max())


def test_tanh_is_torchs_to_round_off_over_the_whole_range():
    g = torch.Generator().manual_seed(0)
    magnitudes = torch.logspace(-30, 30, 20_001, dtype=torch.float64)
    x = torch.cat([magnitudes, -magnitudes, torch.randn(50_000, generator=g) * 3]).float()
    x = torch.cat([x, torch.tensor([0.0, -0.0, float("inf"), float("-inf")])])
    y = Tanh()(x)
    exact = torch.tanh(x.double())
    assert _ulps(y, exact) <= 2.0  # torch's own kernel: 0.5
    assert torch.equal(y[-4:], torch.tensor([0.0, -0.0, 1.0, -1.0]))
    assert torch.equal(torch.signbit(y[-4:]), torch.tensor([False, True, False, True]))
    x64 = x.double()
    torch.testing.assert_close(Tanh()(x64), torch.tanh(x64), rtol=4e-16, atol=0)


def test_tanh_gradient_is_torchs_backward_of_its_output():
    x = (torch.randn(256, 64) * 2).requires_grad_()
    grad = torch.randn(256, 64)
    y = Tanh()(x)
    (g,) = torch.autograd.grad(y, x, grad)
    torch.testing.assert_close(g, grad * (1 - y.detach() ** 2), rtol=0, atol=1e-6)
    (ref,) = torch.autograd.grad(torch.tanh(x), x, grad)
    torch.testing.assert_close(g, ref, rtol=0, atol=1e-6)
    x64 = torch.randn(5, 4, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(Tanh(), (x64,))


def test_tanh_of_a_view_and_of_other_dtypes():
    x = torch.randn(64, 32)
    view = x.t()[::2]  # not contiguous
    torch.testing.assert_close(Tanh()(view), torch.tanh(view), rtol=0, atol=3e-7)
    half = x.bfloat16()
    assert torch.equal(Tanh()(half), torch.tanh(half))  # no NumPy bfloat16: torch's
