"""torch-ppo's training speed against a CleanRL-style PPO on the same torch vector env.

The reference is CleanRL's ``ppo.py`` loop, written here as CleanRL writes it (one ``Agent``
module with a ``get_action_and_value`` method, ``torch.distributions.Categorical`` over masked
logits or ``Normal`` for a Box action, GAE, the clipped surrogate, minibatch epochs), on the same
env (the suite's native torch vector env, ``SAME_STEP`` autoreset), the same members, rollout
length, minibatches, epochs and 64x64 networks. With ``--baseline DIR`` (a checkout of an
older commit, e.g. ``git worktree add --detach /tmp/torch-ppo-base <commit>``) that checkout's
``agents/torch_ppo.py`` is loaded as a second module and timed too, so one run gives the
speed-up of this checkout's loop over the old one. The env alone (uniformly random legal
actions drawn on the device, no learner) is timed as well: the ceiling a learner approaches.

With ``--eval-freq N`` torch-ppo (and the baseline) also run as ``train.py`` runs them, with
an evaluation (``agents.evaluate.evaluate``, ``--eval-episodes`` episodes of the task's single
env, scored against its reference) every N steps: this checkout's on a snapshot of the policy in
a background thread (:mod:`agents.background`), the baseline's inline with the baseline's own
``agents/evaluate.py`` (which solved a game's LP again at every evaluation); this checkout's
evaluations inline too (``+ inline evals``), to tell the background thread's share from the
rest.

Every contender runs in this process, in turns within each round (the first round warms up
and is dropped), with the same seed in a round and ``--threads`` torch threads; the figures are
medians over the rounds of wall-clock and CPU-time (this process, every thread) rates. Printed:
steps/s of each, torch-ppo's ratio to the CleanRL-style loop (target: at least 1.0x) and to the
baseline, and the mean episode return of the last iteration of torch-ppo and of the baseline
(the same algorithm: equal up to the round-off the loops differ by; docs/guide/training.md says
which).

    python benchmarks/ppo_cleanrl.py [--steps 200000] [--repeats 3] [--tasks NAME ...]
        [--baseline DIR] [--eval-freq 0] [--clock wall|cpu] [--threads 1 [2 ...]]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import warnings

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical, Normal

from agents.background import Background
from agents.evaluate import evaluate
from agents.registry import by_gym_id
from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo
from fdia_env.tasks import get as get_task

TASKS = (
    "sparse/tracking-m6-1000004-v0",
    "covariance/ch2-pv-2-v0",
    "sensor-game/m10-strong-defender-v0",
)


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


def env_only(env: gym.vector.VectorEnv, cfg: TorchPPOConfig, seed: int) -> int:
    """Step ``env`` as the learners do, with uniformly random legal actions and no learner."""
    gen = torch.Generator().manual_seed(seed)
    space = env.single_action_space
    box = isinstance(space, gym.spaces.Box)
    low, high = (torch.as_tensor(space.low), torch.as_tensor(space.high)) if box else (0, 0)
    B, steps = cfg.num_envs, cfg.iterations * cfg.num_steps
    env.reset(seed=seed)
    with torch.no_grad():
        for _ in range(steps):
            if box:
                action = low + torch.rand((B, *space.shape), generator=gen) * (high - low)
            else:
                legal = env.action_masks()
                u = torch.rand(legal.shape, generator=gen)
                action = torch.where(legal, u, -1.0).argmax(-1)
            env.step(action)
    return steps * B


def load_baseline(root: Path, name: str = "torch_ppo") -> ModuleType:
    """``root``'s ``agents/<name>.py`` as the module ``<name>_baseline``.

    Its own imports (``agents.checkpoint``, ``agents.registry``, ...) resolve to this
    checkout's.

    Raises:
        FileNotFoundError: When ``root`` holds no ``agents/<name>.py``.
    """
    path = Path(root) / "agents" / f"{name}.py"
    if not path.is_file():
        raise FileNotFoundError(f"--baseline {root}: no agents/{name}.py there")
    spec = importlib.util.spec_from_file_location(f"{name}_baseline", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


Contender = Callable[[gym.vector.VectorEnv, TorchPPOConfig, int], tuple[int, float]]


class Evaluations:
    """What a run's evaluations need: the task's single env, its reference, the schedule."""

    def __init__(self, task_name: str, freq: int, episodes: int) -> None:
        task = get_task(task_name)
        self.env = task.make_env()
        self.reference = by_gym_id(task.env_id).reference_of(self.env)
        self.freq, self.episodes = freq, episodes

    def log(self, evaluate_now: Callable[[Any, int], None]) -> Callable[[dict, Any], None]:
        """A ``log`` callback calling ``evaluate_now(policy, timesteps)`` every ``freq`` steps."""
        due = [self.freq]

        def log(record: dict, policy: Any) -> None:
            if record["timesteps"] >= due[0]:
                due[0] = (record["timesteps"] // self.freq + 1) * self.freq
                evaluate_now(policy, record["timesteps"])

        return log


def _ppo(train: Callable, evals: Evaluations | None = None, old_evaluate: Any = None) -> Contender:
    """A contender running a ``train_torch_ppo`` (this checkout's or the baseline's).

    With ``evals``: evaluations as ``train.py`` makes them, on a snapshot in a background thread
    (this checkout's), or inline with ``old_evaluate`` (the baseline's ``evaluate``, or this
    checkout's to time the background thread's share).
    """

    def run(env: gym.vector.VectorEnv, cfg: TorchPPOConfig, seed: int) -> tuple[int, float]:
        if evals is None:
            result = train(env, cfg, seed=seed)
        elif old_evaluate is not None:

            def inline(policy: Any, timesteps: int) -> None:
                old_evaluate(policy, evals.env, evals.episodes, seed, evals.reference)

            result = train(env, cfg, seed=seed, log=evals.log(inline))
        else:
            with Background() as jobs:

                def deferred(policy: Any, timesteps: int) -> None:
                    snapshot = policy.snapshot()
                    jobs.submit(
                        evaluate, snapshot, evals.env, evals.episodes, seed, evals.reference
                    )

                result = train(env, cfg, seed=seed, log=evals.log(deferred))
                jobs.drain()
        last = result.history[-1]["mean_return"] if result.history else float("nan")
        return result.timesteps, last

    return run


def _plain(run: Callable[[gym.vector.VectorEnv, TorchPPOConfig, int], int]) -> Contender:
    return lambda env, cfg, seed: (run(env, cfg, seed), float("nan"))


def contenders_for(task_name: str, args: argparse.Namespace) -> dict[str, Contender]:
    """The loops timed on a task: torch-ppo, the baseline's, CleanRL-style, the env alone."""
    out: dict[str, Contender] = {"torch-ppo": _ppo(train_torch_ppo)}
    evals = None
    if args.eval_freq:
        evals = Evaluations(task_name, args.eval_freq, args.eval_episodes)
        out["torch-ppo + evaluations"] = _ppo(train_torch_ppo, evals)
        out["torch-ppo + inline evals"] = _ppo(train_torch_ppo, evals, evaluate)
    if args.baseline is not None:
        old = load_baseline(args.baseline).train_torch_ppo
        out["baseline"] = _ppo(old)
        if evals is not None:
            old_evaluate = load_baseline(args.baseline, "evaluate").evaluate
            out["baseline + evaluations"] = _ppo(old, evals, old_evaluate)
    for n in args.threads[1:]:
        out[f"torch-ppo, {n} threads"] = _threads(n, out["torch-ppo"])
    out["CleanRL-style"] = _plain(cleanrl_ppo)
    out["env only"] = _plain(env_only)
    return out


def _threads(n: int, run: Contender) -> Contender:
    """``run`` with ``torch.set_num_threads(n)``, the process's setting restored after it."""

    def threaded(env: gym.vector.VectorEnv, cfg: TorchPPOConfig, seed: int) -> tuple[int, float]:
        before = torch.get_num_threads()
        torch.set_num_threads(n)
        try:
            return run(env, cfg, seed)
        finally:
            torch.set_num_threads(before)

    return threaded


def measure(
    task_name: str, contenders: dict[str, Contender], cfg: TorchPPOConfig, repeats: int
) -> dict[str, tuple[float, float, float]]:
    """Median (wall steps/s, CPU steps/s, last mean return) of each contender on a task.

    The contenders take turns within each round (round 0 warms up and is not counted), with
    the round's number as the seed, each on a fresh env.
    """
    task = get_task(task_name)
    rows: dict[str, list[tuple[float, float, float]]] = {name: [] for name in contenders}
    for r in range(repeats + 1):
        for name, run in contenders.items():
            env = make_torch_env(task.env_id, cfg.num_envs, "cpu", **task.env_kwargs)
            wall, cpu = time.perf_counter(), time.process_time()
            steps, last = run(env, cfg, r)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            env.close()
            if r:
                rows[name].append((steps / wall, steps / cpu, last))
    return {name: tuple(np.median(np.array(v), axis=0)) for name, v in rows.items()}


def main(argv: Sequence[str] | None = None) -> dict[str, dict[str, tuple[float, float, float]]]:
    """Time the loops on each task, in turns, and print the rates and ratios."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=200_000, help="env steps per measurement")
    p.add_argument("--repeats", type=int, default=3, help="measurements per loop (median)")
    p.add_argument("--num-envs", type=int, default=256, help="members B")
    p.add_argument("--num-steps", type=int, default=16, help="rollout length T per member")
    p.add_argument("--tasks", nargs="+", default=list(TASKS), help="benchmark task names")
    p.add_argument(
        "--threads",
        type=int,
        nargs="+",
        default=[1],
        help="torch threads of every loop; more values time torch-ppo with those too",
    )
    p.add_argument("--baseline", type=Path, help="a checkout of an older commit to time too")
    p.add_argument(
        "--eval-freq", type=int, default=0, help="also time runs evaluating every N steps"
    )
    p.add_argument("--eval-episodes", type=int, default=10, help="episodes per evaluation")
    p.add_argument(
        "--clock", choices=("wall", "cpu"), default="wall", help="the clock of the ratios"
    )
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads[0])
    warnings.filterwarnings("ignore", message=".*is out of date.*")  # tasks pin their -v0
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}")
    print(  # its own line: benchmarks/report.py keeps it (the page names the machine once)
        f"settings: {args.threads[0]} torch thread(s); B = {args.num_envs}, T = {args.num_steps}, "
        f"4 minibatches, 4 epochs, 64x64; median of {args.repeats} x {args.steps} steps; "
        f"ratios on {args.clock}-clock rates"
        + (f"; baseline: {args.baseline}" if args.baseline is not None else "")
        + (f"; evaluations every {args.eval_freq:,} steps" if args.eval_freq else "")
    )
    col = 1 if args.clock == "cpu" else 0
    results = {}
    for name in args.tasks:
        cfg = TorchPPOConfig(
            total_timesteps=args.steps,
            num_envs=args.num_envs,
            num_steps=args.num_steps,
            norm_obs=False,
            norm_reward=False,
        )
        rates = measure(name, contenders_for(name, args), cfg, args.repeats)
        results[name] = rates
        print(f"\n{name}")
        print(f"  {'':<25}{'wall':>11}{'CPU':>11}  (steps/s){'last mean return':>22}")
        for who, (wall, cpu, last) in rates.items():
            ret = "" if np.isnan(last) else f"{last:22.6g}"
            print(f"  {who:<25}{wall:>11,.0f}{cpu:>11,.0f}{'':10}{ret}")
        print("  " + "; ".join(f"{a} / {b}: {r:.2f}x" for a, b, r in ratios(rates, col)))
    return results


def ratios(rates: dict[str, tuple[float, float, float]], col: int) -> list[tuple[str, str, float]]:
    """The printed ratios of column ``col`` (0 wall, 1 CPU): torch-ppo to the references."""
    pairs = [("torch-ppo", "CleanRL-style"), ("torch-ppo", "baseline")]
    pairs += [("torch-ppo + evaluations", "baseline + evaluations")]
    pairs += [("torch-ppo + evaluations", "torch-ppo"), ("baseline + evaluations", "baseline")]
    pairs += [("torch-ppo + evaluations", "torch-ppo + inline evals")]
    pairs += [(a, "torch-ppo") for a in rates if a.startswith("torch-ppo, ")]
    pairs += [("torch-ppo", "env only")]
    return [(a, b, rates[a][col] / rates[b][col]) for a, b in pairs if a in rates and b in rates]


if __name__ == "__main__":
    main()
