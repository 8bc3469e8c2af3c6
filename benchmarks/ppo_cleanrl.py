"""torch-ppo's training speed against a CleanRL-style PPO on the same torch vector env.

The reference is CleanRL's ``ppo.py`` loop, written here as CleanRL writes it (one ``Agent``
module with a ``get_action_and_value`` method, ``torch.distributions.Categorical`` over masked
logits or ``Normal`` for a Box action, GAE, the clipped surrogate, minibatch epochs), on the same
env (the suite's native torch vector env, ``SAME_STEP`` autoreset), the same members, rollout
length, minibatches, epochs and 64x64 networks. Both loops run in this process, in turns, one
torch thread; the figure is torch-ppo's steps/s over the reference's (target: at least 1.0x).

    python benchmarks/ppo_cleanrl.py [--steps 200000] [--repeats 3] [--tasks NAME ...]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Sequence

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import warnings

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical, Normal

from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo
from fdia_env.tasks import get as get_task

TASKS = ("sparse/tracking-m6-1000004-v0", "covariance/ch2-pv-2-v0")


def _layer(n_in: int, n_out: int, std: float) -> nn.Linear:
    layer = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


class Agent(nn.Module):
    """CleanRL's ``Agent``: separate tanh MLP actor and critic."""

    def __init__(self, d: int, n: int, box: bool) -> None:
        super().__init__()
        self.box = box
        self.critic = nn.Sequential(
            _layer(d, 64, 2**0.5), nn.Tanh(), _layer(64, 64, 2**0.5), nn.Tanh(), _layer(64, 1, 1.0)
        )
        self.actor = nn.Sequential(
            _layer(d, 64, 2**0.5), nn.Tanh(), _layer(64, 64, 2**0.5), nn.Tanh(), _layer(64, n, 0.01)
        )
        if box:
            self.log_std = nn.Parameter(torch.full((n,), -0.5))

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        """V(x), shape (N, 1)."""
        return self.critic(x)

    def get_action_and_value(self, x, mask=None, action=None):
        """(action, log-probability, entropy, value), drawing the action when None."""
        logits = self.actor(x)
        if self.box:
            dist = Normal(logits, self.log_std.exp().expand_as(logits))
            action = dist.sample() if action is None else action
            return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.critic(x)
        if mask is not None:
            logits = torch.where(mask, logits, torch.tensor(-1e8))
        dist = Categorical(logits=logits)
        action = dist.sample() if action is None else action
        return action, dist.log_prob(action), dist.entropy(), self.critic(x)


def cleanrl_ppo(env: gym.vector.VectorEnv, cfg: TorchPPOConfig, seed: int) -> int:
    """CleanRL ppo.py's loop on ``env`` for ``cfg.total_timesteps``; returns the steps taken."""
    torch.manual_seed(seed)
    B, T = cfg.num_envs, cfg.num_steps
    space = env.single_action_space
    box = isinstance(space, gym.spaces.Box)
    low = torch.as_tensor(space.low) if box else None
    high = torch.as_tensor(space.high) if box else None
    n = int(space.shape[0]) if box else int(space.n)
    d = int(np.prod(env.single_observation_space.shape))
    agent = Agent(d, n, box)
    opt = torch.optim.Adam(agent.parameters(), lr=cfg.learning_rate, eps=1e-5)
    obs = torch.zeros((T, B, d))
    actions = torch.zeros((T, B, n)) if box else torch.zeros((T, B), dtype=torch.long)
    masks = None if box else torch.ones((T, B, n), dtype=torch.bool)
    logprobs, rewards, dones, values = (torch.zeros((T, B)) for _ in range(4))
    next_obs, _ = env.reset(seed=seed)
    next_obs = next_obs.float()
    next_done = torch.zeros(B)
    iterations = cfg.iterations
    for it in range(1, iterations + 1):
        lr = (1.0 - (it - 1.0) / iterations) * cfg.learning_rate
        opt.param_groups[0]["lr"] = lr
        for t in range(T):
            obs[t], dones[t] = next_obs, next_done
            mask = None if box else env.action_masks()
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs, mask)
            values[t], actions[t], logprobs[t] = value.flatten(), action, logprob
            if mask is not None:
                masks[t] = mask
            env_action = low + (action.clamp(-1, 1) + 1) * 0.5 * (high - low) if box else action
            next_obs, reward, term, trunc, _ = env.step(env_action)
            next_obs, rewards[t] = next_obs.float(), reward.float()
            next_done = (term | trunc).float()
        with torch.no_grad():
            next_value = agent.get_value(next_obs).reshape(1, -1)
            advantages = torch.zeros_like(rewards)
            lastgaelam = 0
            for t in reversed(range(T)):
                if t == T - 1:
                    nextnonterminal, nextvalues = 1.0 - next_done, next_value
                else:
                    nextnonterminal, nextvalues = 1.0 - dones[t + 1], values[t + 1]
                delta = rewards[t] + cfg.gamma * nextvalues * nextnonterminal - values[t]
                lastgaelam = delta + cfg.gamma * cfg.gae_lambda * nextnonterminal * lastgaelam
                advantages[t] = lastgaelam
            returns = advantages + values
        b_obs, b_logprobs = obs.reshape(-1, d), logprobs.reshape(-1)
        b_actions = actions.reshape(-1, n) if box else actions.reshape(-1)
        b_masks = None if box else masks.reshape(-1, n)
        b_adv, b_ret = advantages.reshape(-1), returns.reshape(-1)
        batch = B * T
        mb = batch // cfg.num_minibatches
        for _ in range(cfg.update_epochs):
            inds = torch.randperm(batch)
            for start in range(0, batch - mb + 1, mb):
                i = inds[start : start + mb]
                _, newlogprob, entropy, newvalue = agent.get_action_and_value(
                    b_obs[i], None if b_masks is None else b_masks[i], b_actions[i]
                )
                ratio = (newlogprob - b_logprobs[i]).exp()
                adv = (b_adv[i] - b_adv[i].mean()) / (b_adv[i].std() + 1e-8)
                pg = torch.max(
                    -adv * ratio, -adv * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)
                )
                v_loss = 0.5 * ((newvalue.view(-1) - b_ret[i]) ** 2).mean()
                loss = pg.mean() - cfg.ent_coef * entropy.mean() + v_loss * cfg.vf_coef
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), cfg.max_grad_norm)
                opt.step()
    return iterations * B * T


def main(argv: Sequence[str] | None = None) -> None:
    """Time both loops on each task, in turns, and print the ratios."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=200_000, help="env steps per measurement")
    p.add_argument("--repeats", type=int, default=3, help="measurements per loop (median)")
    p.add_argument("--num-envs", type=int, default=256, help="members B")
    p.add_argument("--num-steps", type=int, default=16, help="rollout length T per member")
    p.add_argument("--tasks", nargs="+", default=list(TASKS), help="benchmark task names")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    warnings.filterwarnings("ignore", message=".*is out of date.*")  # tasks pin their -v0
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}")
    print(  # its own line: benchmarks/report.py keeps it (the page names the machine once)
        f"settings: 1 torch thread; B = {args.num_envs}, T = {args.num_steps}, 4 minibatches, "
        f"4 epochs, 64x64; median of {args.repeats} x {args.steps} steps"
    )
    print(f"{'task':<36}{'torch-ppo':>12}{'CleanRL-style':>15}{'ratio':>8}  (steps/s)")
    for name in args.tasks:
        task = get_task(name)
        cfg = TorchPPOConfig(
            total_timesteps=args.steps,
            num_envs=args.num_envs,
            num_steps=args.num_steps,
            norm_obs=False,
            norm_reward=False,
        )
        rates: dict[str, list[float]] = {"ours": [], "cleanrl": []}
        for r in range(args.repeats + 1):  # the first round warms up and is dropped
            for who in ("ours", "cleanrl"):
                env = make_torch_env(task.env_id, args.num_envs, "cpu", **task.env_kwargs)
                t0 = time.perf_counter()
                if who == "ours":
                    steps = train_torch_ppo(env, cfg, seed=r).timesteps
                else:
                    steps = cleanrl_ppo(env, cfg, seed=r)
                if r:
                    rates[who].append(steps / (time.perf_counter() - t0))
        ours, ref = float(np.median(rates["ours"])), float(np.median(rates["cleanrl"]))
        print(f"{name:<36}{ours:>12,.0f}{ref:>15,.0f}{ours / ref:>7.2f}x")


if __name__ == "__main__":
    main()
