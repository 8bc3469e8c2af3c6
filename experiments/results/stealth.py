"""``stealth``: a learned stealthy attacker on IEEE 14 and 118 against the exact optimum.

Attacker rows: stable-baselines3 PPO, or :mod:`agents.torch_ppo` on the env's torch native
vector env (``algo="torch-ppo"``), trained on ``"fdia_env/StealthAttack-v0"`` (``action=
"shift"``: ``MultiBinary(n)``, bit j shifts state j's estimate by ``magnitude``;
``dynamics="expected"``, one snapshot per episode, so the reward is the exact expected damage
``(1 − p) · |K a|_∞``). Its deterministic action's payoff is set against random play and the
optimum:

- IEEE 14 (13 states): the optimum of the action space, found by enumerating all 8,191 non-zero
  shift vectors (exact); random play is their mean.
- IEEE 118 (117 states): 2¹¹⁷ shift vectors cannot be enumerated. The reference is the best
  *undetectable* shift, certified by the security indices: a 0/1 shift is undetectable iff the
  meters it moves fit the budget, and the minimum cut finds, for every state, the fewest meters
  such a shift needs; when the smallest index fits the budget, that shift is played in the env
  and pays ``(1 − α) · magnitude`` (the most any undetectable shift of ``magnitude`` pays, since
  ``K H c = c``). Detectable shifts are not enumerated there (on IEEE 14 none beats it); random
  play is the mean payoff of 4,096 uniform non-zero actions.

Every seed's figure is reported, with the mean and its 95 % CI.

Box-shift rows (``action="box_shift"``: the same bits, shifted as far as ``a_max`` allows) are
scored against the MILP optimum of the budgeted stealthy attack (:func:`milp_reference`:
:func:`baselines.stealth.budgeted_attack` over every state, proved; on IEEE 118 the states
whose min-cut security index exceeds the budget are skipped), which the action space holds on
both grids (the MILP's c is a 0/1 direction). On IEEE 14 the enumeration of every box shift
confirms that no detectable (trimmed) one pays more; on IEEE 118 detectable box shifts are not
enumerated, so a learner could in principle score above 100 %.

Protection rows: the protection game's value (double oracle, certified by its gap) against what
simple protections concede to a best-responding attacker (:func:`baselines.stealth.
protection_exploitability`): protecting the meters of the unprotected optimal attack, and the
first meters of a basic measurement set; and a learned protection (:func:`learned_protection`:
PPO picks the one meter to protect, paid minus the attacker's exact best-response damage),
scored against the game's value.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from experiments.results.common import mean_ci95, write_rows

SCENARIO = "grid-ieee14"
MAGNITUDE = 0.05
ENUMERABLE = 16
"""Largest number of states whose shift vectors are enumerated (2^16 − 1 actions)."""


A_MAX = 0.5
"""Largest injection per meter (pu) of the box-shift rows and of the MILP they are scored by."""
ACTIONS = ("shift", "box_shift")


def _env_kwargs(
    budget: int, scenario: str = SCENARIO, action: str = "shift", a_max: float = A_MAX
) -> dict[str, Any]:
    size = {"magnitude": MAGNITUDE} if action == "shift" else {"a_max": a_max}
    return {
        "scenario": scenario,
        "budget": budget,
        "action": action,
        **size,
        "dynamics": "expected",
        "horizon": 1,
    }


def _payoffs(venv: Any, bits: np.ndarray) -> np.ndarray:
    """Exact expected payoff of each row of ``bits`` (shift actions) in ``venv``'s env."""
    a = venv.injections(bits)
    damage = np.max(np.abs(a @ venv.env.estimation.K.T), axis=1)
    p = np.asarray(venv.env.estimation.detection_probability(a))
    return (1.0 - p) * damage


def shift_payoffs(budget: int, scenario: str = SCENARIO) -> np.ndarray:
    """(2^n − 1,) exact expected payoff of every non-zero shift action (bits in binary order)."""
    from fdia_env.stealth.vector import StealthVectorEnv

    venv = StealthVectorEnv(1, **_env_kwargs(budget, scenario))
    n = venv.env.estimation.n
    if n > ENUMERABLE:
        raise ValueError(f"{scenario} has {n} states: 2^{n} shifts are too many to enumerate")
    bits = ((np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    return _payoffs(venv, bits)


def references(budget: int, scenario: str = SCENARIO, seed: int = 0) -> dict[str, Any]:
    """The optimum (and how it is known) and random play's mean payoff for one setting."""
    from fdia_env.stealth.vector import StealthVectorEnv

    venv = StealthVectorEnv(1, **_env_kwargs(budget, scenario))
    est = venv.env.estimation
    if est.n <= ENUMERABLE:
        payoffs = shift_payoffs(budget, scenario)
        return {
            "optimum": float(np.max(payoffs)),
            "optimum_kind": f"enumerated ({payoffs.size:,} shifts)",
            "random": float(np.mean(payoffs)),
        }
    from baselines.stealth import security_index

    si = security_index(est, method="mincut")
    k = int(np.argmin(si.indices))
    if si.indices[k] > budget:
        raise ValueError(
            f"budget={budget}: every undetectable shift on {scenario} needs at least "
            f"{int(si.indices[k])} meters, so no certified reference is known"
        )
    bits = (np.abs(si.shifts[k]) > 0.5).astype(np.int8)[None, :]
    best = float(_payoffs(venv, bits)[0])
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, 2, (4096, est.n)).astype(np.int8)
    draws = draws[draws.any(axis=1)]
    return {
        "optimum": best,
        "optimum_kind": (
            f"best undetectable shift (min cut: state {k}, {int(si.indices[k])} meters)"
        ),
        "random": float(np.mean(_payoffs(venv, draws))),
    }


def milp_reference(
    budget: int,
    scenario: str = SCENARIO,
    time_limit: float | None = None,
    seed: int = 0,
    a_max: float = A_MAX,
) -> dict[str, Any]:
    """The MILP optimum of the budgeted stealthy attack, as the box-shift env pays it.

    :func:`baselines.stealth.budgeted_attack` (``a_max``, pu) over every state: the
    exact MILP over every shift c (not only 0/1 directions). On a grid with more than
    :data:`ENUMERABLE` states the states whose minimum-cut security index exceeds the budget
    are skipped (no undetectable attack on ``budget`` meters moves them; the cut is exact with
    every branch flow and bus injection metered, as on the presets). The env pays an
    undetectable attack ``(1 − α) · shift``, so the optimum is ``(1 − α)`` times the MILP's
    value, and its certified bound ``(1 − α)`` times the MILP's bound. The MILP's attack is
    played in the env as a box shift when its c is a 0/1 direction (``attained``): then the
    env's action space holds the MILP optimum. Random play: the mean over every non-zero box
    shift (IEEE 14) or over 4,096 uniform ones.
    """
    from baselines.stealth import budgeted_attack, security_index
    from fdia_env.stealth.vector import StealthVectorEnv

    venv = StealthVectorEnv(1, **_env_kwargs(budget, scenario, "box_shift", a_max))
    est = venv.env.estimation
    start = time.perf_counter()
    index = security_index(est, method="mincut") if est.n > ENUMERABLE else None
    attack = budgeted_attack(est, budget, a_max=a_max, indices=index, time_limit=time_limit)
    seconds = time.perf_counter() - start
    keep = 1.0 - est.alpha
    c = np.asarray(attack.c)
    top = float(np.max(np.abs(c))) if c.size else 0.0
    bits = (np.abs(c) > 0.5 * top).astype(np.int8)
    played = float(_payoffs(venv, bits[None, :])[0]) if top > 0.0 else 0.0
    binary = top > 0.0 and np.allclose(np.abs(c), top * bits, rtol=0.0, atol=1e-9 * top)
    if est.n <= ENUMERABLE:
        draws = ((np.arange(1, 2**est.n)[:, None] >> np.arange(est.n)) & 1).astype(np.int8)
    else:
        draws = np.random.default_rng(seed).integers(0, 2, (4096, est.n)).astype(np.int8)
        draws = draws[draws.any(axis=1)]
    skipped = 0 if index is None else int(np.sum(index.lower_bounds > budget))
    return {
        "optimum": keep * attack.value,
        "bound": keep * float(attack.bound),
        "proved": attack.proved,
        "a_max": a_max,
        "milp_shift": attack.value,
        "milp_state": attack.target,
        "milp_meters": list(attack.meters),
        "milp_seconds": seconds,
        "skipped_states": skipped,
        "attained": bool(binary and abs(played - keep * attack.value) <= 1e-9),
        "optimum_kind": (
            f"MILP, {'proved' if attack.proved else 'bound ' + format(keep * attack.bound, '.4f')}"
            f": state {attack.target}, meters {list(attack.meters)}"
            + (f", {skipped} states skipped by min cut" if skipped else "")
        ),
        "random": float(np.mean(_payoffs(venv, draws))),
    }


def _payoff(
    budget: int,
    action: np.ndarray,
    scenario: str = SCENARIO,
    kind: str = "shift",
    a_max: float = A_MAX,
) -> float:
    from fdia_env.stealth import stealth_attack_v0

    env = stealth_attack_v0.parallel_env(**_env_kwargs(budget, scenario, kind, a_max))
    env.reset(seed=0)
    _, rewards, *_ = env.step({"attacker": np.asarray(action, dtype=np.int8)})
    return float(rewards["attacker"])


ALGOS = ("PPO", "torch-ppo")
"""Learners of :func:`learned_attacker`. MaskablePPO does not apply: the env offers no action
mask (``action_masks`` is None, every shift is legal) and the shift space is ``MultiBinary``."""

TORCH_ENVS = 64
"""Members of the torch vector env that ``algo="torch-ppo"`` trains on."""


class _ShiftBox:
    """The torch native vector env's attacker with a ``Box(-1, 1, (n,))`` action (bit j = a_j > 0).

    :func:`agents.torch_ppo.train_torch_ppo` needs ``Discrete`` or ``Box`` actions; the
    stealth env's shifts are ``MultiBinary``. The env runs in ``SAME_STEP`` autoreset (with one
    snapshot per episode, ``horizon=1``, every member ends and restarts each step); the adapter
    thresholds the Gaussian action.
    """

    def __init__(
        self, budget: int, scenario: str, num_envs: int, kind: str = "shift", a_max: float = A_MAX
    ) -> None:
        import gymnasium as gym

        from fdia_env.stealth.vector import StealthVectorEnv

        self.inner = StealthVectorEnv(
            num_envs,
            backend="torch",
            device="cpu",
            autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
            **_env_kwargs(budget, scenario, kind, a_max),
        )
        n = self.inner.env.estimation.n
        self.num_envs, self.backend, self.device = num_envs, "torch", "cpu"
        self.metadata = self.inner.metadata
        self.single_observation_space = self.inner.single_observation_space
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (n,), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        return self.inner.reset(seed=seed)

    def step(self, actions: Any) -> tuple:
        return self.inner.step((actions > 0).to(int))

    def close(self) -> None:
        self.inner.close()


def _train(
    algo: str,
    budget: int,
    steps: int,
    seed: int,
    scenario: str,
    kind: str = "shift",
    a_max: float = A_MAX,
) -> tuple[Any, float]:
    """Train ``algo`` for ``steps`` env steps; (its deterministic shift action, train seconds)."""
    if algo == "torch-ppo":
        import torch

        from agents.torch_ppo import TorchPPOConfig, train_torch_ppo

        venv = _ShiftBox(budget, scenario, TORCH_ENVS, kind, a_max)
        config = TorchPPOConfig(total_timesteps=steps, num_envs=TORCH_ENVS, num_steps=4)
        torch.set_num_threads(1)
        result = train_torch_ppo(venv, config, seed=seed)  # type: ignore[arg-type]
        obs, _ = venv.reset(seed=seed)
        mean, _ = result.policy.predict(obs[0].numpy(), deterministic=True)
        venv.close()
        return (mean > 0).astype(np.int8), result.train_seconds
    import gymnasium as gym
    from stable_baselines3 import PPO

    import fdia_env  # noqa: F401 - registers the ids

    env = gym.make("fdia_env/StealthAttack-v0", **_env_kwargs(budget, scenario, kind, a_max))
    start = time.perf_counter()
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=seed, verbose=0)
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - start
    obs, _ = env.reset(seed=seed)
    action, _ = model.predict(obs, deterministic=True)
    env.close()
    return action, seconds


def learned_attacker(
    budget: int,
    steps: int,
    seeds: list[int],
    scenario: str = SCENARIO,
    algo: str = "PPO",
    action: str = "shift",
    time_limit: float | None = None,
    a_max: float = A_MAX,
) -> dict[str, Any]:
    """A learner's payoff per seed against random play and the optimum (see the module docstring).

    Args:
        budget: Meters the attacker holds.
        steps: Env steps of training per seed.
        seeds: Training seeds.
        scenario: Grid preset.
        algo: ``"PPO"`` (stable-baselines3, ``MultiBinary`` shifts) or ``"torch-ppo"``
            (:mod:`agents.torch_ppo` on the torch native vector env, 64 members, a Gaussian
            policy over ``Box(-1, 1, (n,))`` whose positive entries are the shifted states).
        action: The env's ``"shift"`` (of :data:`MAGNITUDE`, scored by :func:`references`)
            or ``"box_shift"`` (as far as ``a_max`` = :data:`A_MAX` allows, scored by the MILP
            optimum of the budgeted stealthy attack, :func:`milp_reference`).
        time_limit: HiGHS seconds per state of that MILP (``None``: solved to optimality).
        a_max: The box shift's largest injection per meter (pu), the MILP's bound.

    Raises:
        ValueError: For an ``algo`` other than those of :data:`ALGOS`, an ``action`` other
            than those of :data:`ACTIONS`.
    """
    if algo not in ALGOS:
        raise ValueError(
            f"algo must be one of {list(ALGOS)}, got {algo!r} (MaskablePPO does not apply: the "
            "stealth env offers no action mask)"
        )
    if action not in ACTIONS:
        raise ValueError(f"action must be one of {list(ACTIONS)}, got {action!r}")
    if action == "shift":
        ref = references(budget, scenario)
    else:
        ref = milp_reference(budget, scenario, time_limit, a_max=a_max)
    learned, seconds = [], []
    for seed in seeds:
        bits, secs = _train(algo, budget, steps, seed, scenario, action, a_max)
        seconds.append(secs)
        learned.append(_payoff(budget, bits, scenario, action, a_max))
    mean, ci = mean_ci95(learned)
    best = ref["optimum"]
    return {
        **{k: v for k, v in ref.items() if k not in ("optimum", "optimum_kind", "random")},
        "action": action,
        "algo": algo,
        "scenario": scenario,
        "budget": budget,
        "steps": steps,
        "seeds": seeds,
        "learned": learned,
        "learned_mean": mean,
        "learned_ci95": ci,
        "random": ref["random"],
        "optimum": best,
        "optimum_kind": ref["optimum_kind"],
        "score": [v / best for v in learned],
        "train_seconds": seconds,
    }


def threshold_game(budget: int, false_alarm_cost: float = 1.0) -> dict[str, Any]:
    """The threshold game on IEEE 14's shift actions, solved exactly (enumeration + LP).

    The defender picks the false-alarm rate α among the env's ``alphas``; its loss is the
    attacker's expected damage ``(1 − p_α(a)) · |K a|_∞`` plus ``false_alarm_cost · α``. The α
    term does not depend on the attacker's action, so the game is the zero-sum game of that
    loss (the attacker's best responses are unchanged), whose value the LP gives.
    """
    from scipy import optimize

    from fdia_env.stealth.vector import StealthVectorEnv

    venv = StealthVectorEnv(1, **_env_kwargs(budget))
    env = venv.env
    n = env.estimation.n
    bits = ((np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    a = venv.injections(bits)
    damage = np.max(np.abs(a @ env.estimation.K.T), axis=1)
    loss = np.array(
        [
            (1.0 - np.asarray(est.detection_probability(a))) * damage + false_alarm_cost * est.alpha
            for est in env._estimations
        ]
    )  # (rates, actions): the defender's expected loss
    rates = len(env.alphas)
    # min v s.t. x' loss[:, j] <= v for every j, x a distribution over the rates
    res = optimize.linprog(
        np.r_[np.zeros(rates), 1.0],
        A_ub=np.c_[loss.T, -np.ones(loss.shape[1])],
        b_ub=np.zeros(loss.shape[1]),
        A_eq=np.r_[np.ones(rates), 0.0][None],
        b_eq=[1.0],
        bounds=[(0, None)] * rates + [(None, None)],
        method="highs",
    )
    mix = np.clip(res.x[:rates], 0.0, None)
    return {
        "alphas": list(env.alphas),
        "loss": loss,
        "value": float(res.x[rates]),
        "defender": (mix / mix.sum()).tolist(),
        "concedes": loss.max(axis=1).tolist(),  # each pure rate against a best response
    }


def learned_defender(
    budget: int, steps: int, seeds: list[int], false_alarm_cost: float = 1.0
) -> dict[str, Any]:
    """PPO on the defender's view (its attacker plays at random) against the game value.

    Each seed's deterministic rate is scored by what it concedes to a best-responding attacker
    (its row's largest loss), set against the value of the threshold game.
    """
    import gymnasium as gym
    from stable_baselines3 import PPO

    import fdia_env  # noqa: F401 - registers the ids
    from fdia_env.stealth import DEFENDER_GYM_ID

    game = threshold_game(budget, false_alarm_cost)
    picked, concedes, seconds = [], [], []
    for seed in seeds:
        env = gym.make(DEFENDER_GYM_ID, **_env_kwargs(budget), false_alarm_cost=false_alarm_cost)
        start = time.perf_counter()
        model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=seed, verbose=0)
        model.learn(total_timesteps=steps)
        seconds.append(time.perf_counter() - start)
        obs, _ = env.reset(seed=seed)
        action, _ = model.predict(obs, deterministic=True)
        picked.append(game["alphas"][int(action)])
        concedes.append(game["concedes"][int(action)])
        env.close()
    mean, ci = mean_ci95(concedes)
    return {
        "kind": "defender",
        "budget": budget,
        "steps": steps,
        "seeds": seeds,
        "false_alarm_cost": false_alarm_cost,
        "alpha": picked,
        "concedes": concedes,
        "concedes_mean": mean,
        "concedes_ci95": ci,
        "value": game["value"],
        "game_defender": game["defender"],
        "alphas": game["alphas"],
        "train_seconds": seconds,
    }


def protection_rows(budget: int, protection: int) -> dict[str, Any]:
    """The game's value against two simple protections, on IEEE 14 with ``a_max = 0.5``."""
    from baselines.stealth import (
        basic_measurement_set,
        budgeted_attack,
        protection_exploitability,
        protection_game,
    )
    from fdia_env.stealth import static_estimation

    est = static_estimation("ieee14")
    start = time.perf_counter()
    game = protection_game(est, budget, protection, a_max=0.5)
    seconds = time.perf_counter() - start
    attack = budgeted_attack(est, budget, a_max=0.5)
    on_attack = attack.meters[:protection]
    basic = basic_measurement_set(est)[:protection]
    return {
        "budget": budget,
        "protection": protection,
        "value": game.value,
        "gap": game.gap,
        "iterations": game.iterations,
        "seconds": seconds,
        "defender": {str(k): v for k, v in game.defender.items()},
        "protect_optimal_attack": list(on_attack),
        "protect_optimal_attack_concedes": protection_exploitability(
            est, on_attack, budget, a_max=0.5
        )[0],
        "protect_basic": list(basic),
        "protect_basic_concedes": protection_exploitability(est, basic, budget, a_max=0.5)[0],
        "unprotected": attack.value,
    }


LEARNING_RATE = 0.01
"""PPO's step size in :func:`learned_protection` (the one-step bandit; SB3's 3e-4 leaves the
stochastic mix near uniform after 1,024 steps)."""


def _protect_one_env(payoffs: np.ndarray) -> Any:
    """A one-step ``gymnasium.Env``: pick the meter to protect, paid ``payoffs[action]``."""
    import gymnasium as gym

    class ProtectOneMeter(gym.Env):
        """One step per episode, a constant observation; reward ``payoffs[action]``."""

        def __init__(self) -> None:
            self.payoffs = np.asarray(payoffs, dtype=float)
            self.observation_space = gym.spaces.Box(0.0, 1.0, (1,), dtype=np.float32)
            self.action_space = gym.spaces.Discrete(self.payoffs.size)

        def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
            super().reset(seed=seed)
            return np.zeros(1, dtype=np.float32), {}

        def step(self, action: Any) -> tuple:
            reward = float(self.payoffs[int(action)])
            return np.zeros(1, dtype=np.float32), reward, True, False, {}

    return ProtectOneMeter()


def protection_payoffs(budget: int = 3, estimation: Any = "ieee14") -> np.ndarray:
    """(m,) the defender's payoff for protecting each single meter, ``a_max = 0.5``.

    Minus the attacker's exact best-response damage against that protection
    (:func:`baselines.stealth.protection_exploitability`, one MILP per meter, certified).
    """
    from baselines.stealth import protection_exploitability
    from fdia_env.stealth import static_estimation

    est = static_estimation(estimation) if isinstance(estimation, str) else estimation
    damage = [protection_exploitability(est, [j], budget, a_max=0.5)[0] for j in range(est.m)]
    return 0.0 - np.array(damage)  # 0.0 - d: no -0.0 where a meter stops every attack


def learned_protection(
    budget: int = 3,
    protection: int = 1,
    steps: int = 2048,
    seeds: list[int] | None = None,
    *,
    payoffs: Any = None,
    samples: int = 1000,
) -> dict[str, Any]:
    """SB3 PPO picks the meter to protect on IEEE 14 (``a_max = 0.5``) against the game value.

    The defender's payoff for protecting meter j is minus the damage of the attacker's exact
    best response to it (:func:`protection_payoffs`, computed once per call); PPO learns on a
    one-step env with ``Discrete(m)`` actions, a constant observation and that payoff as reward.
    Per seed the row reports the deterministic action (the meter), what it concedes, the
    empirical mix of ``samples`` stochastic actions and what that mix concedes to a
    best-responding attacker (:func:`baselines.stealth.protection_exploitability` on the mix),
    against the value of :func:`baselines.stealth.protection_game` (no time limit: certified).

    Args:
        budget: Meters the attacker may corrupt.
        protection: Meters the defender protects; only 1 (one ``Discrete(m)`` action).
        steps: PPO env steps per seed (> 0).
        seeds: Training seeds (default ``[0, 1, 2]``).
        payoffs: Injected (m,) payoffs (tests): then the game and the mix's exact score are
            skipped (``value``, ``mix_concedes`` are None) and the pure actions concede
            ``-payoffs[j]``.
        samples: Stochastic actions drawn for the empirical mix (> 0).

    Raises:
        ValueError: Naming ``protection`` (other than 1), ``steps``, ``samples``, ``seeds`` or
            ``payoffs`` (not a non-empty finite 1-d vector).
    """
    from stable_baselines3 import PPO

    if isinstance(protection, bool) or protection != 1:
        raise ValueError(
            f"protection must be 1 (the learner picks one meter: Discrete(m)), got {protection!r}"
        )
    for name, v in (("steps", steps), ("samples", samples)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an int >= 1, got {v!r}")
    seeds = [0, 1, 2] if seeds is None else list(seeds)
    if not seeds or not all(isinstance(s, (int, np.integer)) and s >= 0 for s in seeds):
        raise ValueError(f"seeds must be a non-empty list of ints >= 0, got {seeds!r}")
    est = None
    payoff_seconds = 0.0
    if payoffs is None:
        from fdia_env.stealth import static_estimation

        est = static_estimation("ieee14")
        start = time.perf_counter()
        pay = protection_payoffs(budget, est)
        payoff_seconds = time.perf_counter() - start
    else:
        pay = np.asarray(payoffs, dtype=float)
        if pay.ndim != 1 or pay.size == 0 or not np.all(np.isfinite(pay)):
            raise ValueError(f"payoffs must be a non-empty finite 1-d vector, got {payoffs!r}")
    m = pay.size
    meters, concedes, mixes, mix_concedes, seconds = [], [], [], [], []
    for seed in seeds:
        env = _protect_one_env(pay)
        start = time.perf_counter()
        model = PPO(
            "MlpPolicy",
            env,
            learning_rate=LEARNING_RATE,
            n_steps=128,
            batch_size=64,
            seed=seed,
            verbose=0,
        )
        model.learn(total_timesteps=steps)
        seconds.append(time.perf_counter() - start)
        obs = np.zeros((1, 1), dtype=np.float32)
        j = int(model.predict(obs, deterministic=True)[0][0])
        meters.append(j)
        concedes.append(0.0 - float(pay[j]))
        model.set_random_seed(seed)
        drawn = model.predict(np.zeros((samples, 1), dtype=np.float32), deterministic=False)[0]
        counts = np.bincount(np.asarray(drawn, dtype=int), minlength=m)
        mix = {(int(k),): float(c / samples) for k, c in enumerate(counts) if c}
        mixes.append({str(k[0]): p for k, p in mix.items()})
        if est is not None:
            from baselines.stealth import protection_exploitability

            mix_concedes.append(protection_exploitability(est, mix, budget, a_max=0.5)[0])
        else:
            mix_concedes.append(None)
        env.close()
    value = gap = game_seconds = None
    if est is not None:
        from baselines.stealth import protection_game

        start = time.perf_counter()
        game = protection_game(est, budget, protection, a_max=0.5)
        game_seconds = time.perf_counter() - start
        value, gap = game.value, game.gap
    best = float(pay.max())
    return {
        "kind": "protection_learner",
        "budget": budget,
        "protection": protection,
        "steps": steps,
        "seeds": seeds,
        "samples": samples,
        "payoffs": pay.tolist(),
        "best_meters": np.flatnonzero(pay >= best - 1e-12).tolist(),
        "best_concedes": 0.0 - best,
        "meter": meters,
        "concedes": concedes,
        "mix": mixes,
        "mix_concedes": mix_concedes,
        "value": value,
        "gap": gap,
        "train_seconds": seconds,
        "payoff_seconds": payoff_seconds,
        "game_seconds": game_seconds,
    }


def format_rows(
    attackers: list[dict],
    protections: list[dict],
    defenders: list[dict] | None = None,
    protectors: list[dict] | None = None,
) -> str:
    """The rows as Markdown tables."""
    lines = [
        f"Attacker (shift actions of {MAGNITUDE} rad, expected dynamics):",
        "",
        "| grid | learner | budget | steps | learned per seed (rad) | mean ± 95 % CI | random "
        "| optimum | learned / optimum per seed | train s per seed |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    boxed = [r for r in attackers if r.get("action") == "box_shift"]
    attackers = [r for r in attackers if r.get("action") != "box_shift"]
    for r in attackers:
        per = ", ".join(f"{v:.4f}" for v in r["learned"])
        ratio = ", ".join(f"{s:.1%}" for s in r["score"])
        secs = ", ".join(f"{s:.0f}" for s in r["train_seconds"])
        lines.append(
            f"| {r['scenario']} | {r.get('algo', 'PPO')} | {r['budget']} | {r['steps']:,} | "
            f"{per} | "
            f"{r['learned_mean']:.4f} ± {r['learned_ci95']:.2g} | {r['random']:.2e} | "
            f"{r['optimum']:.4f} ({r['optimum_kind']}) | {ratio} | {secs} |"
        )
    if boxed:
        lines += [
            "",
            "Attacker against the MILP optimum (box shifts, expected dynamics; the env pays "
            "(1 − α) · shift for an undetectable attack):",
            "",
            "| grid | learner | budget | a_max (pu) | steps | learned per seed (rad) | mean ± 95 % "
            "CI | random | MILP optimum (bound) | MILP s | learned / optimum per seed "
            "| train s per seed |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in boxed:
            lines.append(
                f"| {r['scenario']} | {r['algo']} | {r['budget']} | {r.get('a_max', A_MAX):g} | "
                f"{r['steps']:,} | {', '.join(f'{v:.4f}' for v in r['learned'])} | "
                f"{r['learned_mean']:.4f} ± {r['learned_ci95']:.2g} | {r['random']:.2e} | "
                f"{r['optimum']:.4f} ({r['bound']:.4f}; {r['optimum_kind']}) | "
                f"{r['milp_seconds']:.0f} | {', '.join(f'{v:.1%}' for v in r['score'])} | "
                f"{', '.join(f'{v:.0f}' for v in r['train_seconds'])} |"
            )
    lines += [
        "",
        "Protection game (IEEE 14, a_max = 0.5 pu; damage in rad a best-responding attacker gets):",
        "",
        "| attacker meters | protected | game value (gap) | protect the optimal attack's meters "
        "| protect basic-set meters | nothing protected |",
        "|---|---|---|---|---|---|",
    ]
    for r in protections:
        lines.append(
            f"| {r['budget']} | {r['protection']} | {r['value']:.4f} ({r['gap']:.1e}) | "
            f"{r['protect_optimal_attack_concedes']:.4f} | {r['protect_basic_concedes']:.4f} | "
            f"{r['unprotected']:.4f} |"
        )
    if defenders:
        lines += [
            "",
            "Learned threshold defender (PPO on the defender's view, IEEE 14, attacker budget 3; "
            "loss = the attacker's expected damage + false_alarm_cost · α against a "
            "best-responding attacker):",
            "",
            "| steps | α picked per seed | loss conceded per seed | mean ± 95 % CI | game value "
            "| train s per seed |",
            "|---|---|---|---|---|---|",
        ]
        for r in defenders:
            lines.append(
                f"| {r['steps']:,} | {', '.join(f'{a:g}' for a in r['alpha'])} | "
                f"{', '.join(f'{v:.5f}' for v in r['concedes'])} | {r['concedes_mean']:.5f} ± "
                f"{r['concedes_ci95']:.2g} | {r['value']:.5f} | "
                f"{', '.join(f'{v:.0f}' for v in r['train_seconds'])} |"
            )
    if protectors:
        lines += [
            "",
            "Learned protection (SB3 PPO on a one-step Discrete(m) env, reward = minus the "
            "attacker's exact best-response damage; IEEE 14, a_max = 0.5 pu, damage in rad):",
            "",
            "| attacker meters | protected | steps | meter per seed | concedes per seed "
            "| stochastic mix concedes per seed | game value (gap) | train s per seed |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in protectors:
            mixed = ", ".join("-" if v is None else f"{v:.4f}" for v in r["mix_concedes"])
            value = "-" if r["value"] is None else f"{r['value']:.4f} ({r['gap']:.1e})"
            lines.append(
                f"| {r['budget']} | {r['protection']} | {r['steps']:,} | "
                f"{', '.join(str(j) for j in r['meter'])} | "
                f"{', '.join(f'{v:.4f}' for v in r['concedes'])} | {mixed} | {value} | "
                f"{', '.join(f'{v:.0f}' for v in r['train_seconds'])} |"
            )
    return "\n".join(lines)


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``stealth`` tables; ``quick``: IEEE 14, budget 3, 2 seeds, 2,048 steps, no game.

    The full run (its budgets fit one session on 2 shared cores): 3 seeds of each learner for
    the attacker (budget 3): SB3 PPO on IEEE 14 (4,096 and 8,192 steps) and IEEE 118 (2,048
    steps), torch PPO on IEEE 14 and IEEE 118 (16,384 and 65,536 steps each); against the
    MILP, box shifts: torch PPO on both grids at ``a_max`` 0.5 and 0.05 (65,536 steps) and
    at 0.05 (262,144 steps), SB3 PPO at 0.05 (4,096 steps on IEEE 14, 2,048 on IEEE 118); 3 seeds
    of 1,024 steps for the threshold defender, the two protection games, and 3 seeds of 1,024
    steps for the learned protection (attacker budget 3, one meter protected).
    """
    seeds = [seed, seed + 1, seed + 2]
    if quick:
        attackers = [learned_attacker(3, 2048, seeds[:2])]
        protections: list[dict] = []
        defenders: list[dict] = []
        protectors: list[dict] = []
    else:
        attackers = [
            learned_attacker(3, 4096, seeds),
            learned_attacker(3, 8192, seeds),
            learned_attacker(3, 2048, seeds, "grid-ieee118"),
            learned_attacker(3, 16384, seeds, algo="torch-ppo"),
            learned_attacker(3, 65536, seeds, algo="torch-ppo"),
            learned_attacker(3, 16384, seeds, "grid-ieee118", algo="torch-ppo"),
            learned_attacker(3, 65536, seeds, "grid-ieee118", algo="torch-ppo"),
        ]
        box = {"algo": "torch-ppo", "action": "box_shift"}
        for grid in (SCENARIO, "grid-ieee118"):
            for a_max in (A_MAX, 0.05):
                attackers.append(learned_attacker(3, 65536, seeds, grid, a_max=a_max, **box))
        for grid in (SCENARIO, "grid-ieee118"):
            attackers.append(learned_attacker(3, 262144, seeds, grid, a_max=0.05, **box))
        for grid, steps in ((SCENARIO, 4096), ("grid-ieee118", 2048)):
            attackers.append(
                learned_attacker(3, steps, seeds, grid, action="box_shift", a_max=0.05)
            )
        defenders = [learned_defender(3, 1024, seeds)]
        protections = [protection_rows(3, 1), protection_rows(5, 2)]
        protectors = [learned_protection(3, 1, 1024, seeds)]
    if out is not None:
        write_rows(out / "stealth.json", [*attackers, *defenders, *protections, *protectors])
    return format_rows(attackers, protections, defenders, protectors)
