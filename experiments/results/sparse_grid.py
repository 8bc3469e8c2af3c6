"""``sparse_grid``: sparse attacks on power grids, learned against the heuristics and the optimum.

For each instance (a DC grid model, meter-level or bus-level (RTU) sensors, budget c, window N,
objective Φ = tr or log det of ``P[K+N|K+N]``): SFS, SBS, SFS-SS and DP
(:mod:`baselines.sparse`), the certified optimum of ``branch_and_bound`` (split bound; when it is
not proved within its time limit, the best set found and the certified upper bound), and two
learners trained on the identical instance, 3 seeds each: sb3-contrib's MaskablePPO (the
project's SB3 model, :func:`agents.algos.build_model` with the defaults of
:data:`agents.config.ALGO_DEFAULTS`, its rewards rescaled as ``train.py`` rescales them on the
grid presets: attacking nothing 0, the optimum 1) and the torch PPO
(:func:`agents.torch_ppo.train_torch_ppo` with torch-ppo's defaults; it scales its own
rewards). Both play the env's own sequential format with the options ``train.py`` trains each
preset with (:data:`agents.config.SCENARIO_DEFAULTS`, :func:`train_py_defaults`): on the grid
presets plan-first with the picks in increasing order
(``gymnasium.make("fdia_env/SparseAttack-v2", action="sequential", order="increasing")``:
masked picks of sensor-time pairs, each above the last, then stop, then the plan plays out), on
dc-ieee14-50 in the plan order with the state groups (``order="plan", groups="state"``, and
``ent_coef`` 0.05); torch PPO on its native vector env,
since the bitmask ``Discrete(2**M)`` is too large for these learners at M = 14 and, above 16
sensors, the ``MultiBinary(M)`` action has no mask.

Scores, the project's (:meth:`agents.registry.Reference.ratio`): value / optimum for the trace,
the determinant ratio ``exp(Φ − Φ*)`` for log det. Where only a bound is known, a score is given
against the best known value and as "≥ x % of the bound" (a lower bound on the true score).
"""

from __future__ import annotations

import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from experiments.results.common import mean_ci95, write_rows
from fdia_env.systems import LinearSystem

GYM_ID = "fdia_env/SparseAttack-v2"
ENV = "sparse_attack_v0"
"""The env family's key in :data:`agents.config.SCENARIO_DEFAULTS`."""

OBJECTIVES = ("trace", "logdet")
EXS_MAX_SETS = 200_000  # below this many attack sets EXS also runs (a check of B&B)


def _ieee14_bus() -> LinearSystem:
    from fdia_env.systems import grid_system

    return grid_system("ieee14", sensors="bus")


def _preset(name: str) -> Callable[[], LinearSystem]:
    def build() -> LinearSystem:
        from fdia_env import scenarios

        return scenarios.get(name).system

    return build


# system key -> (description, sensors, builder)
SYSTEMS: dict[str, tuple[str, str, Callable[[], LinearSystem]]] = {
    "ieee14-rtu": ("pandapower IEEE 14, one RTU per bus", "bus", _ieee14_bus),
    "dc-ieee14-50": (
        "dc-ieee14-50 preset (DC IEEE 14), 50 meters",
        "meter",
        _preset("dc-ieee14-50"),
    ),
    "grid-ieee14": ("grid-ieee14 preset (pandapower), 34 meters", "meter", _preset("grid-ieee14")),
    "grid-ieee30": ("grid-ieee30 preset (pandapower), 71 meters", "meter", _preset("grid-ieee30")),
    "grid-ieee118": (
        "grid-ieee118 preset (pandapower), 304 meters",
        "meter",
        _preset("grid-ieee118"),
    ),
}


@dataclass(frozen=True)
class Instance:
    """One sparse-attack instance of the table.

    Attributes:
        system: A key of :data:`SYSTEMS`.
        budget: c.
        horizon: N.
        objective: ``"trace"`` or ``"logdet"``.
        bnb_limit: Seconds of branch and bound (None: until proved).
    """

    system: str
    budget: int
    horizon: int
    objective: str
    bnb_limit: float | None = 60.0

    def __post_init__(self) -> None:
        if self.system not in SYSTEMS:
            raise ValueError(f"system must be one of {sorted(SYSTEMS)}, got {self.system!r}")
        for name in ("budget", "horizon"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        lim = self.bnb_limit
        if lim is not None and (
            isinstance(lim, bool) or not isinstance(lim, int | float) or not lim > 0
        ):
            raise ValueError(f"bnb_limit must be a positive number or None, got {lim!r}")

    @property
    def label(self) -> str:
        """Short label, e.g. ``ieee14-rtu c=6 N=6 logdet``."""
        return f"{self.system} c={self.budget} N={self.horizon} {self.objective}"


@dataclass(frozen=True)
class Budget:
    """Training budget of one learner run (per seed).

    Attributes:
        maskable_steps: MaskablePPO env steps (decisions).
        torch_steps: torch-ppo env steps.
        torch_envs: torch-ppo vector members B.
        evals: Evaluations along training (learning curve points).
    """

    maskable_steps: int
    torch_steps: int
    torch_envs: int = 256
    evals: int = 10

    def __post_init__(self) -> None:
        for name in ("maskable_steps", "torch_steps", "torch_envs", "evals"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")


FULL_INSTANCES = (
    Instance("ieee14-rtu", 6, 6, "logdet"),
    Instance("dc-ieee14-50", 5, 6, "trace"),
    Instance("grid-ieee14", 5, 9, "logdet"),
    Instance("grid-ieee30", 6, 4, "trace", bnb_limit=30.0),
    Instance("grid-ieee118", 6, 3, "trace", bnb_limit=30.0),
)
FULL_BUDGET = Budget(maskable_steps=25_000, torch_steps=200_000)
QUICK_INSTANCE = Instance("ieee14-rtu", 3, 3, "logdet")
QUICK_BUDGET = Budget(maskable_steps=6_000, torch_steps=60_000, evals=3)
CURVE_INSTANCE = FULL_INSTANCES[0]  # the learning-curve plot's hard instance
SEEDS = 3


def ratio(value: float, reference: float, objective: str) -> float:
    """The project's score of ``value`` against ``reference``: ratio, or det ratio for log det."""
    if objective == "logdet":
        return math.exp(value - reference)
    return value / reference


def solve(inst: Instance, system: LinearSystem) -> dict[str, Any]:
    """SFS, SBS, SFS-SS, DP, branch and bound (and EXS when small) on ``inst``.

    Returns:
        ``values`` and ``seconds`` per solver, the B&B ``proved``, ``bound``, ``gap`` and
        ``nodes``, ``optimum`` (the B&B value when proved, else the best value known: of B&B's
        incumbent and the heuristics),
        the B&B attack set, SFS's result, and ``exs`` (None when not run).
    """
    from baselines.sparse import branch_and_bound, dp, exhaustive, sbs, sfs, sfs_ss

    args = (system, inst.budget, inst.horizon, inst.objective)
    values, seconds, results = {}, {}, {}
    for name, fn in (("SFS", sfs), ("SBS", sbs), ("SFS-SS", sfs_ss), ("DP", dp)):
        t = time.perf_counter()
        results[name] = fn(*args)
        seconds[name] = time.perf_counter() - t
        values[name] = results[name].value
    t = time.perf_counter()
    proof = branch_and_bound(*args, time_limit=inst.bnb_limit)
    seconds["B&B"] = time.perf_counter() - t
    exs = None
    if math.comb(system.M * inst.horizon, inst.budget) <= EXS_MAX_SETS:
        t = time.perf_counter()
        exs = exhaustive(*args).value
        seconds["EXS"] = time.perf_counter() - t
    # where the optimum is not proved a heuristic may beat the B&B incumbent: the best known
    best = proof.value if proof.proved_optimal else max(proof.value, *values.values())
    return {
        "values": values,
        "seconds": seconds,
        "optimum": best,
        "proved": bool(proof.proved_optimal),
        "bound": float(proof.upper_bound),
        "gap": float(proof.gap),
        "nodes": int(proof.nodes),
        "bnb": proof,
        "sfs": results["SFS"],
        "exs": exs,
    }


def train_py_defaults(inst: Instance) -> Any:
    """``train.py``'s defaults on ``inst``'s preset (:class:`agents.config.ScenarioDefaults`).

    Those of ``inst.system`` where :data:`agents.config.SCENARIO_DEFAULTS` has them
    (dc-ieee14-50: the plan order with the state groups), else the grid presets' (the bus-level
    ieee14-rtu trains as ``grid-ieee14-rtu`` does).
    """
    from agents.config import SCENARIO_DEFAULTS

    found = SCENARIO_DEFAULTS.get((ENV, inst.system))
    return found if found is not None else SCENARIO_DEFAULTS[(ENV, "grid-ieee14")]


def env_kwargs(system: LinearSystem, inst: Instance, order: str | None = None) -> dict[str, Any]:
    """The options of the learners' env: ``inst`` in the sequential format.

    Args:
        system: ``inst``'s system.
        inst: The instance.
        order: The decision order (its other options left at the env's defaults), or None for
            ``train.py``'s options on the preset (:func:`train_py_defaults`).
    """
    if order is None:
        options = dict(train_py_defaults(inst).env_kwargs)
    else:
        options = {"action": "sequential", "order": order}
    return {
        "scenario": system,
        "budget": inst.budget,
        "horizon": inst.horizon,
        "objective": inst.objective,
        **options,
    }


def make_env(system: LinearSystem, inst: Instance, order: str | None = None) -> Any:
    """The learners' Gymnasium env of ``inst`` (see :func:`env_kwargs`)."""
    import gymnasium as gym

    return gym.make(GYM_ID, **env_kwargs(system, inst, order))


def plan_policy(result: Any) -> Any:
    """A solver's attack set played in the learners' env (plan-first order)."""
    from fdia_env.envs.sequential import PlanOrderPolicy

    return PlanOrderPolicy.from_result(result)


def _play(policy: Any, env: Any, episodes: int = 1, seed: int = 0) -> float:
    from agents.evaluate import evaluate

    return evaluate(policy, env, episodes, seed, reference=1.0).mean


def replay_native(result: Any, system: LinearSystem, inst: Instance) -> float:
    """The return of ``result.policy()`` in ``sparse_attack_v0`` itself (its own action format).

    Built with :func:`fdia_env.tasks.task.make_pinned`: v0 on purpose, so Gymnasium's
    out-of-date notice for it is not printed.
    """
    from agents.evaluate import evaluate
    from fdia_env.tasks.task import make_pinned

    kwargs = {"budget": inst.budget, "horizon": inst.horizon, "objective": inst.objective}
    env = make_pinned("fdia_env/SparseAttack-v0", None, {"scenario": system, **kwargs})
    try:
        return evaluate(result.policy(), env, 1, 0, reference=1.0).mean
    finally:
        env.close()


def _nothing_return(env: Any) -> float:
    """The return of attacking nothing in the learners' env (stop at every decision)."""
    env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(0)
        total += float(reward)
        done = terminated or truncated
    return total


def training_env(
    system: LinearSystem,
    inst: Instance,
    order: str | None = None,
    reference: float | None = None,
) -> Any:
    """MaskablePPO's training env of ``inst``: one member, its rewards rescaled.

    As ``train.py`` on the grid presets (:class:`agents.training.NormalizedReward`): an
    episode attacking nothing returns 0 and one reaching ``reference`` returns 1. Without
    ``reference``, or when it is no better than attacking nothing, SB3's ``VecNormalize``
    scales the rewards instead.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.training import NormalizedReward

    if reference is not None:
        probe = make_env(system, inst, order)
        nothing = _nothing_return(probe)
        probe.close()
        scale = abs(reference - nothing)
        if scale > 1e-12 * max(1.0, abs(reference)):
            return DummyVecEnv(
                [lambda: NormalizedReward(make_env(system, inst, order), nothing, scale)]
            )
    return VecNormalize(
        DummyVecEnv([lambda: make_env(system, inst, order)]),
        norm_obs=False,
        norm_reward=True,
        gamma=1.0,
    )


def train_py_hyperparameters(inst: Instance | None = None, algo: str = "MaskablePPO") -> Any:
    """``algo``'s hyperparameters as ``train.py`` sets them on ``inst``'s preset for one env.

    The algorithm's defaults (:data:`agents.config.ALGO_DEFAULTS`) with the preset's own
    (:func:`train_py_defaults`; without ``inst`` the grid presets'), so that the results train
    as ``train.py --num-envs 1`` does (its default there trains 8 native members, with 128
    decisions each per rollout and minibatches of 256).
    """
    from agents.config import SCENARIO_DEFAULTS, Hyperparameters, with_defaults

    defaults = SCENARIO_DEFAULTS[(ENV, "grid-ieee14")] if inst is None else train_py_defaults(inst)
    return with_defaults(algo, Hyperparameters(), defaults)


def train_maskable(
    system: LinearSystem,
    inst: Instance,
    budget: Budget,
    seed: int,
    order: str | None = None,
    reference: float | None = None,
) -> tuple[Any, list[tuple[int, float]], float]:
    """MaskablePPO in ``order``: ``(model, curve [(steps, return)], train seconds)``.

    Trained as ``train.py`` trains on the preset: its options and hyperparameters there
    (``order`` None; :func:`env_kwargs`, :func:`train_py_hyperparameters`) and the rewards
    rescaled so that attacking nothing returns 0 and ``reference`` 1 (:func:`training_env`).
    """
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.algos import build_model
    from agents.config import algo_kwargs

    torch.set_num_threads(1)
    eval_env = make_env(system, inst, order)
    venv = training_env(system, inst, order, reference)
    model = build_model(
        "MaskablePPO", venv, algo_kwargs("MaskablePPO", train_py_hyperparameters(inst)), seed
    )
    every = max(1, budget.maskable_steps // budget.evals)
    curve: list[tuple[int, float]] = []

    class Curve(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % every == 0:
                curve.append((self.num_timesteps, _play(self.model, eval_env)))
            return True

    start = time.perf_counter()
    model.learn(budget.maskable_steps, callback=Curve())
    seconds = time.perf_counter() - start
    if not curve or curve[-1][0] != model.num_timesteps:
        curve.append((model.num_timesteps, _play(model, eval_env)))
    venv.close()
    eval_env.close()
    return model, curve, seconds


def train_torch(
    system: LinearSystem, inst: Instance, budget: Budget, seed: int, norm_obs: bool = False
) -> tuple[Any, list[tuple[int, float]], float]:
    """torch-ppo on the native vector env: ``(policy, curve [(steps, return)], seconds)``.

    torch-ppo's defaults with the preset's as ``train.py`` sets them
    (:func:`train_py_hyperparameters`), observations not normalised (``norm_obs``): with its
    running normalisation torch-ppo reached 46.4 % of the optimum on ieee14-rtu in the
    plan-first order (seed 0, 200,000 steps), without it 100 % (docs/guide/sparse.md).
    """
    import dataclasses

    import torch

    from agents.config import TORCH_PPO, resolved_hyperparameters
    from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo

    torch.set_num_threads(1)
    hp = resolved_hyperparameters(TORCH_PPO, train_py_hyperparameters(inst, TORCH_PPO))
    config = TorchPPOConfig.from_hyperparameters(hp, budget.torch_steps, budget.torch_envs)
    config = dataclasses.replace(config, norm_obs=norm_obs)
    eval_env = make_env(system, inst)
    venv = make_torch_env(GYM_ID, budget.torch_envs, "cpu", **env_kwargs(system, inst))
    every = max(1, config.iterations // budget.evals)
    curve: list[tuple[int, float]] = []

    def log(record: dict[str, float], policy: Any) -> None:
        if record["iteration"] % every == 0 or record["iteration"] == config.iterations:
            curve.append((int(record["timesteps"]), _play(policy, eval_env)))

    result = train_torch_ppo(venv, config, seed=seed, log=log)
    venv.close()
    eval_env.close()
    return result.policy, curve, result.train_seconds


ORDER_INSTANCES = FULL_INSTANCES[:3]
"""The decision-order study's instances: those whose optimum branch and bound proves."""


def order_study(
    instances: tuple[Instance, ...] = ORDER_INSTANCES,
    orders: tuple[str, ...] = ("plan", "time"),
    seeds: tuple[int, ...] = (0, 1, 2),
    steps: int = 20_000,
) -> list[dict[str, Any]]:
    """MaskablePPO in each decision order of the sequential format, scored against B&B.

    One row per (instance, order, seed): the final deterministic policy's score (the project's
    ratio to branch and bound's optimum), SFS's score and the training seconds; each row is
    printed as it comes (docs/guide/sparse.md shows the numbers)::

        python -c "from experiments.results.sparse_grid import order_study; order_study()"
    """
    from baselines.sparse import branch_and_bound, sfs

    budget = Budget(maskable_steps=steps, torch_steps=1, evals=1)
    rows = []
    for inst in instances:
        system = SYSTEMS[inst.system][2]()
        args = (system, inst.budget, inst.horizon, inst.objective)
        best = branch_and_bound(*args, time_limit=inst.bnb_limit).value
        greedy = ratio(sfs(*args).value, best, inst.objective)
        for order in orders:
            for seed in seeds:
                _, curve, secs = train_maskable(system, inst, budget, seed, order, best)
                score = ratio(curve[-1][1], best, inst.objective)
                row = {"instance": inst.label, "order": order, "seed": seed}
                row.update(sfs=greedy, score=score, seconds=secs)
                print(row, flush=True)
                rows.append(row)
    return rows


def run_instance(
    inst: Instance, budget: Budget, seeds: list[int], random_episodes: int = 200
) -> dict[str, Any]:
    """Solve ``inst``, train both learners per seed, score everything; one table row."""
    t0 = time.perf_counter()
    system = SYSTEMS[inst.system][2]()
    sol = solve(inst, system)
    opt, obj = sol["optimum"], inst.objective
    env = make_env(system, inst)
    sfs_plan = _play(plan_policy(sol["sfs"]), env)
    bnb_plan = _play(plan_policy(sol["bnb"]), env)
    sfs_native = replay_native(sol["sfs"], system, inst)
    random_return = _play("random", env, random_episodes, seeds[0])
    env.close()
    solve_seconds = time.perf_counter() - t0
    learners: dict[str, Any] = {}
    trainers = (("MaskablePPO", partial(train_maskable, reference=opt)), ("torch-ppo", train_torch))
    for name, trainer in trainers:
        runs = []
        for s in seeds:
            _, curve, secs = trainer(system, inst, budget, s)
            runs.append({"seed": s, "value": curve[-1][1], "curve": curve, "seconds": secs})
        scores = [ratio(r["value"], opt, obj) for r in runs]
        mean, half = mean_ci95(scores)
        bound_scores = [ratio(r["value"], sol["bound"], obj) for r in runs]
        learners[name] = {
            "runs": runs,
            "scores": scores,
            "mean": mean,
            "ci95": half,
            "bound_mean": float(np.mean(bound_scores)),
            "seconds": float(sum(r["seconds"] for r in runs)),
        }
    return {
        "instance": inst.label,
        "system": inst.system,
        "description": SYSTEMS[inst.system][0],
        "sensors": SYSTEMS[inst.system][1],
        "M": system.M,
        "n": system.n,
        "budget": inst.budget,
        "horizon": inst.horizon,
        "objective": obj,
        "pairs": system.M * inst.horizon,
        "values": sol["values"],
        "heuristic_scores": {k: ratio(v, opt, obj) for k, v in sol["values"].items()},
        "heuristic_bound_scores": {
            k: ratio(v, sol["bound"], obj) for k, v in sol["values"].items()
        },
        "optimum": opt,
        "proved": sol["proved"],
        "bound": sol["bound"],
        "gap": sol["gap"],
        "nodes": sol["nodes"],
        "bnb_attacks": [list(p) for p in sol["bnb"].attacks],
        "exs": sol["exs"],
        "solver_seconds": sol["seconds"],
        "sfs_plan_return": sfs_plan,
        "sfs_native_return": sfs_native,
        "bnb_plan_return": bnb_plan,
        "random_return": random_return,
        "random_score": ratio(random_return, opt, obj),
        "learners": learners,
        "solve_seconds": solve_seconds,
        "wall_seconds": time.perf_counter() - t0,
    }


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _heur(row: dict[str, Any], name: str) -> str:
    s = row["heuristic_scores"][name]
    if row["proved"]:
        return "100 %" if abs(s - 1) < 1e-9 else _pct(s)
    return f"{_pct(s)} (≥ {_pct(row['heuristic_bound_scores'][name])})"


def _learner(row: dict[str, Any], name: str) -> str:
    ln = row["learners"][name]
    half = "" if math.isnan(ln["ci95"]) else f" ± {100 * ln['ci95']:.1f}"
    text = f"{100 * ln['mean']:.1f}{half} %"
    if not row["proved"]:
        text += f" (≥ {_pct(ln['bound_mean'])} of the bound)"
    return text


def format_rows(rows: list[dict[str, Any]]) -> str:
    """The rows as Markdown: the scores table, then the wall-time table."""
    lines = [
        "| instance | sensors | M, n | c, N | Φ | pairs | SFS | SBS | SFS-SS | DP "
        "| certified optimum | MaskablePPO | torch PPO | random |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["proved"]:
            cert = f"{r['optimum']:.6g} (proved, {r['nodes']} nodes)"
        else:
            cert = (
                f"best known {r['optimum']:.6g}, bound {r['bound']:.6g} "
                f"(gap {_pct(r['gap'])}, not proved)"
            )
        lines.append(
            f"| {r['system']} | {r['sensors']} | {r['M']}, {r['n']} | {r['budget']}, "
            f"{r['horizon']} | {r['objective']} | {r['pairs']} | "
            + " | ".join(_heur(r, k) for k in ("SFS", "SBS", "SFS-SS", "DP"))
            + f" | {cert} | {_learner(r, 'MaskablePPO')} | {_learner(r, 'torch-ppo')} "
            f"| {_pct(r['random_score'])} |"
        )
    lines += [
        "",
        "| instance | SFS / SBS / SFS-SS / DP (s) | B&B (s) | MaskablePPO (s, all seeds) "
        "| torch PPO (s, all seeds) | row wall (s) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        s = r["solver_seconds"]
        lines.append(
            f"| {r['instance']} | "
            + " / ".join(f"{s[k]:.1f}" for k in ("SFS", "SBS", "SFS-SS", "DP"))
            + f" | {s['B&B']:.1f} | {r['learners']['MaskablePPO']['seconds']:.0f} "
            f"| {r['learners']['torch-ppo']['seconds']:.0f} | {r['wall_seconds']:.0f} |"
        )
    return "\n".join(lines)


def plot_curves(row: dict[str, Any], path: Path) -> Path:
    """Learning curves (score per seed, mean line) with the optimum and SFS as horizontal lines."""
    import matplotlib.pyplot as plt

    from agents.plots import save_figure

    fig, ax = plt.subplots(figsize=(7, 4))
    opt, obj = row["optimum"], row["objective"]
    for (name, ln), color in zip(row["learners"].items(), ("C0", "C1"), strict=True):
        for run in ln["runs"]:
            steps = [p[0] for p in run["curve"]]
            ax.plot(steps, [ratio(p[1], opt, obj) for p in run["curve"]], color=color, alpha=0.35)
        ax.plot([], [], color=color, label=f"{name} ({len(ln['runs'])} seeds)")
    ax.axhline(1.0, color="k", ls="--", label="certified optimum (B&B)")
    sfs = row["heuristic_scores"]["SFS"]
    ax.axhline(sfs, color="C3", ls=":", label=f"SFS ({_pct(sfs)})")
    ax.set_xscale("log")
    ax.set_xlabel("environment steps (plan decisions)")
    ax.set_ylabel("score (det ratio to the optimum)" if obj == "logdet" else "score")
    ax.set_title(f"sparse attack, {row['instance']}")
    ax.set_ylim(-0.02, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    return save_figure(fig, path)


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``sparse_grid`` table (Markdown); ``quick``: one small instance, 1 seed, short runs."""
    start = time.perf_counter()
    if quick:
        instances, budget, seeds = (QUICK_INSTANCE,), QUICK_BUDGET, [seed]
    else:
        instances, budget, seeds = FULL_INSTANCES, FULL_BUDGET, [seed + i for i in range(SEEDS)]
    rows = []
    for inst in instances:
        rows.append(run_instance(inst, budget, seeds))
        if out is not None:  # after every instance, so a long run keeps what it has done
            write_rows(out / "sparse_grid.json", rows)
        if not quick:
            print(f"sparse_grid: {inst.label} done at {time.perf_counter() - start:.0f} s",
                  file=sys.stderr, flush=True)  # fmt: skip
    if out is not None:
        if not quick:
            curve_row = next(r for r in rows if r["instance"] == CURVE_INSTANCE.label)
            plot_curves(curve_row, out / "results_sparse_grid_curve.png")
    wall = time.perf_counter() - start
    return (
        format_rows(rows)
        + f"\n\nWall time {wall:.0f} s on {platform.processor() or platform.machine()}, "
        f"{len(seeds)} seed(s) per learner, MaskablePPO {budget.maskable_steps} steps, "
        f"torch PPO {budget.torch_steps} steps (B = {budget.torch_envs})."
    )


def last_step_values(
    system: LinearSystem, budget: int, horizon: int, objective: str = "trace"
) -> tuple[np.ndarray, np.ndarray]:
    """Φ of every attack set of exactly ``budget`` sensors, all at the window's last step.

    The filter runs ``horizon − 1`` steps with every sensor from the steady state (as the sparse
    env and ``baselines.sparse`` start), then the last step without the set's sensors. With
    scalar sensors, dropping a set S from the full information ``A`` at the last step is a rank
    ``|S|`` downdate (Woodbury): with ``u_i = H_i' R_i^{-1/2}``, ``K = U' A⁻¹ U`` and
    ``L = U' A⁻² U``, ``tr (A − U_S U_S')⁻¹ = tr A⁻¹ + tr((I − K_SS)⁻¹ L_SS)`` and
    ``log det (A − U_S U_S')⁻¹ = −log det A − log det(I − K_SS)``. Batched over all
    ``C(M, budget)`` sets (2,118,760 for dc-ieee14-50, a few seconds).

    Returns:
        ``(sets, values)``: (C(M, budget), budget) sensor indices in ``itertools.combinations``
        order and their Φ.

    Raises:
        ValueError: For a sensor with more than one measurement row, a budget outside 1..M, a
            horizon < 1 or an unknown objective.
    """
    import itertools

    from baselines.sparse import make_problem
    from fdia_env.kalman.filter import information_update, predict_cov

    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if any(s.H.shape[0] != 1 for s in system.sensors):
        raise ValueError("system must have scalar sensors (one measurement row each)")
    M = system.M
    if isinstance(budget, bool) or not isinstance(budget, int) or not 1 <= budget <= M:
        raise ValueError(f"budget must be an integer in 1..{M}, got {budget!r}")
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"horizon must be an integer >= 1, got {horizon!r}")
    P = make_problem(system, budget, horizon).P_start
    for _ in range(horizon - 1):
        P = information_update(predict_cov(P, system.F, system.Q), system.J)
    A = np.linalg.inv(predict_cov(P, system.F, system.Q)) + system.J.sum(axis=0)
    A_inv = np.linalg.inv(A)
    U = np.stack([s.H[0] / np.sqrt(s.R[0, 0]) for s in system.sensors], axis=1)  # (n, M)
    K, L = U.T @ A_inv @ U, U.T @ A_inv @ A_inv @ U
    sets = np.array(list(itertools.combinations(range(M), budget)), dtype=np.intp)
    values = np.empty(len(sets))
    eye = np.eye(budget)
    for lo in range(0, len(sets), 250_000):  # chunks: (chunk, c, c) blocks
        s = sets[lo : lo + 250_000]
        rows, cols = s[:, :, None], s[:, None, :]
        D = eye - K[rows, cols]
        if objective == "trace":
            values[lo : lo + len(s)] = np.trace(A_inv) + np.einsum(
                "bii->b", np.linalg.solve(D, L[rows, cols])
            )
        else:
            values[lo : lo + len(s)] = -np.linalg.slogdet(A)[1] - np.linalg.slogdet(D)[1]
    return sets, values


def landscape(name: str = "dc-ieee14-50", budget: int = 5, horizon: int = 6) -> str:
    """Why the learners stop at SFS's set on a preset: its last-step attack sets, counted.

    Every set of ``budget`` sensors at the last step (:func:`last_step_values`, trace), scored
    against the best of them (Φ / Φ*), grouped by how many of the best set's own sensors (those
    not in SFS's set) it holds, and by how many of SFS's own: the best score in each group is
    the path a learner that builds a set one sensor at a time can climb.

    Returns:
        Markdown lines.
    """
    from baselines.sparse import sfs
    from fdia_env import scenarios

    system = scenarios.get(name).system
    sets, values = last_step_values(system, budget, horizon)
    best = values.max()
    score = values / best
    top = sets[values.argmax()]
    greedy = sfs(system, budget, horizon)
    if any(k != horizon - 1 for k, _ in greedy.attacks):
        raise ValueError("SFS's set attacks before the last step: the table does not apply")
    sfs_set = np.array(sorted(i for _, i in greedy.attacks))
    sfs_score = greedy.value / best
    own_top, own_sfs = np.setdiff1d(top, sfs_set), np.setdiff1d(sfs_set, top)
    lines = [
        f"{name}, c = {budget}, N = {horizon}, trace: {len(sets):,} sets of the last step; best "
        f"{best:.9g} (sensors {top.tolist()}, 0-based), SFS {sfs_score:.2%} "
        f"(sensors {sfs_set.tolist()}); {int((score > sfs_score + 1e-12).sum())} sets beat "
        f"SFS, {int((score >= 0.99).sum())} reach 99 %",
        "",
        f"| k | sets with k of {own_top.tolist()} (the best set's own) | best score | worst "
        f"| sets with k of {own_sfs.tolist()} (SFS's own) | best score |",
        "|---|---|---|---|---|---|",
    ]
    in_top, in_sfs = np.isin(sets, own_top).sum(1), np.isin(sets, own_sfs).sum(1)
    for k in range(max(len(own_top), len(own_sfs)) + 1):
        a, b = in_top == k, in_sfs == k
        cells = [f"{int(a.sum()):,}", f"{score[a].max():.2%}", f"{score[a].min():.2%}"]
        cells = cells if a.any() else ["0", "-", "-"]
        other = [f"{int(b.sum()):,}", f"{score[b].max():.2%}"] if b.any() else ["0", "-"]
        lines.append(f"| {k} | " + " | ".join(cells + other) + " |")
    return "\n".join(lines)
