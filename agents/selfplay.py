"""Equilibrium finding with learned best responses on a one-shot two-player game.

Each iteration trains a fresh SB3 learner (PPO, A2C or DQN) for each side on its Gymnasium view
against the other side's current mixed strategy (a :class:`~fdia_env.envs.opponents.FixedMix`),
then updates the mixes:

- ``ibr`` (iterated best response): each side's mix is its latest best response;
- ``fsp`` (fictitious self-play): the uniform average of all its best responses so far;
- ``psro`` (policy-space response oracles, Lanctot et al., NeurIPS 2017): the learned policies
  form two populations; their payoff against each other is measured by playing them in the env
  (the empirical meta-game), and ``baselines.game.solve_zero_sum`` (the LP) gives the meta mix
  over each population.

In the one-shot game a policy acts once, on the constant initial observation, so a learned
deterministic policy is a pure strategy (its action there) and a mix over policies is a mixed
strategy over actions. After every iteration the exploitability of the current pair is measured
exactly on ``baselines.game.payoff_matrix`` (:func:`baselines.game.exploitability`). In the
typed sensor game (``--env-kwargs types '["independent","dependent"]' priors '[0.5,0.5]'
attacker_model uninformed``) the matrix is the Bayesian game's ``L̄ = Σ_s p_s L_s`` and the
meta-game's payoffs are exact averages over nature's draw; the informed-attacker game is not a
matrix game over the attacker's actions and is refused.

The learned policies are saved as ``policies/<side>_<k>.pt`` / ``.json`` in the format of
:mod:`agents.checkpoint` (tensors and JSON; loading unpickles nothing) and ``state.json`` holds
the iterations done, so ``--resume`` continues after the last finished iteration. Older runs'
``policies/*.zip`` load only with ``--trust-checkpoint``. SIGINT/SIGTERM stop after the best
response being trained (the unfinished iteration is dropped) and the scores of the finished
iterations are written.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.algos import build_model
from agents.checkpoint import (
    inside,
    load_model,
    read_json,
    require_trusted,
    save_model,
)
from agents.config import (
    GameConfig,
    algo_kwargs,
    check_device_available,
    parse_env_kwargs,
    resolved_hyperparameters,
)
from agents.evaluate import Evaluation, evaluate
from agents.interrupt import StopRequest, StopTrainingCallback, stop_on_signals
from agents.plots import exploitability_curve
from agents.registry import Reference, Trainable, game_names, get
from agents.runs import (
    check_not_shorter,
    check_resumable,
    config_dict,
    new_run_dir,
    remove_stale_temp_files,
    removed_unless,
    resume_dir,
    run_lock,
    run_prefix,
    write_json,
)
from agents.seeding import derived_seed, seed_everything
from agents.training import check_env_kwargs, env_thunk, make_env, make_logger
from baselines.game import MixedStrategyPolicy, exploitability, solve_zero_sum
from fdia_env.envs.opponents import FixedMix

METHODS = ("psro", "fsp", "ibr")
SIDES = ("attacker", "defender")
STATE = "state.json"  # a game run folder that --resume can continue has it


@dataclass
class SelfPlayResult:
    """What :func:`run_selfplay` returns.

    Attributes:
        run_dir: The run folder.
        method: ``"psro"``, ``"fsp"`` or ``"ibr"``.
        x: (m,) the defender's final mixed strategy over its actions.
        y: (n,) the attacker's final mixed strategy.
        value: The game value (LP).
        history: One record per iteration (exploitabilities, NashConv, best responses).
        evaluations: Final evaluations (learned mixes and the LP equilibrium) by row name.
        populations: The learned pure strategies (actions) of each side, in order.
        train_seconds: Wall time of the iterations.
        interrupted: The signal (SIGINT 2, SIGTERM 15) that stopped the run early, or None.
    """

    run_dir: Path
    method: str
    x: np.ndarray
    y: np.ndarray
    value: float
    history: list[dict[str, Any]]
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    populations: dict[str, list[int]] = field(default_factory=dict)
    train_seconds: float = 0.0
    interrupted: int | None = None


def one_hot(action: int, n: int) -> np.ndarray:
    """The pure strategy ``action`` as an (n,) probability vector."""
    out = np.zeros(n)
    out[action] = 1.0
    return out


def mix_of(population: list[int], weights: np.ndarray, n: int) -> np.ndarray:
    """The mixed strategy over actions of a weighted population of pure strategies."""
    out = np.zeros(n)
    np.add.at(out, population, weights)
    return out / out.sum()


def current_mixes(
    method: str, pops: dict[str, list[int]], n: dict[str, int], meta: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The defender's and attacker's strategies after an iteration of ``method``.

    ``"ibr"``: each side's last best response; ``"fsp"``: the uniform mix over each population;
    ``"psro"``: the equilibrium of the meta-game ``meta`` (populations × populations) spread
    over the actions.
    """
    if method == "ibr":
        return one_hot(pops["defender"][-1], n["defender"]), one_hot(
            pops["attacker"][-1], n["attacker"]
        )
    if method == "fsp":
        weights = {side: np.ones(len(pops[side])) for side in ("defender", "attacker")}
    else:
        sx, sy, _ = solve_zero_sum(meta)
        weights = {"defender": sx, "attacker": sy}
    return (
        mix_of(pops["defender"], weights["defender"], n["defender"]),
        mix_of(pops["attacker"], weights["attacker"], n["attacker"]),
    )


def initial_action(model: BaseAlgorithm, entry: Trainable, env_kwargs: dict[str, Any]) -> int:
    """The pure strategy of a learned policy: its deterministic action at the initial state."""
    with entry.make(**env_kwargs) as env:
        obs, _ = env.reset(seed=0)
    return int(model.predict(obs, deterministic=True)[0])


def learn_best_response(
    entry: Trainable,
    env_kwargs: dict[str, Any],
    opponent: np.ndarray,
    algo: str,
    kwargs: dict[str, Any],
    steps: int,
    seed: int,
    device: str = "cpu",
    tb_dir: Path | None = None,
    callback: BaseCallback | None = None,
) -> tuple[BaseAlgorithm, int]:
    """A fresh ``algo`` learner trained against the fixed mix ``opponent``, and its action.

    The learner plays ``entry``'s side; the action is its pure strategy (:func:`initial_action`).
    ``callback`` may end training early (as :class:`~agents.interrupt.StopTrainingCallback`).
    """
    seed_everything(seed)
    make = env_thunk(
        entry.gym_id,
        env_kwargs,
        lambda: FixedMix(opponent, seed=derived_seed(seed, 1)),
        monitor=True,
    )
    vec_env = DummyVecEnv([make])
    model = build_model(algo, vec_env, kwargs, seed, device)
    if tb_dir is not None:  # a resumed iteration replaces the unfinished one's events
        model.set_logger(make_logger(tb_dir, purge_from=0))
    model.learn(steps, callback=callback)
    vec_env.close()
    if tb_dir is not None:
        model.logger.close()
    return model, initial_action(model, entry, env_kwargs)


def empirical_payoff(
    attacker: BaseAlgorithm,
    defender: BaseAlgorithm,
    entry: Trainable,
    env_kwargs: dict[str, Any],
    n_episodes: int,
    seed: int,
) -> float:
    """The attacker's mean return when the two learned policies play each other in the env.

    In the typed sensor game (``types=``) the mean is exact over nature's draw: one episode per
    type, forced with ``reset(options={"attacker_type": s})``, weighted by the priors (the
    one-shot expected-dynamics payoff of two deterministic policies does not vary otherwise).
    """
    with entry.view(opponent=defender, **env_kwargs) as env:
        priors = getattr(env.unwrapped.parallel.attack, "priors", None)
        if priors is None:
            return evaluate(attacker, env, n_episodes, seed, reference=None).mean
        total = 0.0
        for s, p in enumerate(priors):
            obs, _ = env.reset(seed=seed, options={"attacker_type": s})
            action, _ = attacker.predict(obs, deterministic=True)
            _, reward, *_ = env.step(int(action))
            total += float(p) * float(reward)
        return total


def _report_line(rec: dict[str, Any]) -> str:
    return (
        f"iter {rec['iteration']:3d}  steps {rec['timesteps']:8d}  "
        f"BR attacker {rec['br_attacker']} (gap {rec['br_gap_attacker']:.3g})  "
        f"BR defender {rec['br_defender']} (gap {rec['br_gap_defender']:.3g})  "
        f"expl def {rec['defender']:.4f} att {rec['attacker']:.4f}  "
        f"NashConv {rec['nash_conv']:.4f} ({rec['relative_nash_conv']:.2%} of value)"
    )


def game_prefix(cfg: GameConfig) -> str:
    """Run folder name without its time: ``<env>-<method>-<algo>-s<seed>``."""
    algo = get(cfg.env, "attacker").algorithm(cfg.algo)
    return run_prefix(f"{cfg.env}-{cfg.method}", algo, cfg.run.seed)


def policy_names(state: dict[str, Any]) -> dict[str, list[str]]:
    """The saved policy files of each side that ``state.json`` lists.

    Runs made before the safe format list none: their policies are ``<side>_<k>.zip``.
    """
    pops = state["populations"]
    names = state.get("policies") or {
        side: [f"{side}_{k}.zip" for k in range(len(pops[side]))] for side in SIDES
    }
    for side in SIDES:
        if not isinstance(names.get(side), list) or len(names[side]) != len(pops[side]):
            raise ValueError(f"{STATE}: the policies of {side} do not match its population")
    return names


def load_policies(
    run_dir: Path,
    names: dict[str, list[str]],
    entries: dict[str, Trainable],
    env_kwargs: dict[str, Any],
    algo: str,
    kwargs: dict[str, Any],
    device: str = "cpu",
    trusted: bool = False,
) -> dict[str, list[BaseAlgorithm]]:
    """The saved policies of both sides, rebuilt from ``algo`` and ``kwargs``.

    Every file is checked (inside ``run_dir/policies``, present, not pickle-based unless
    ``trusted``) before any is loaded.

    Raises:
        ValueError: For a file outside the run folder, missing or corrupt.
        UntrustedCheckpointError: For an SB3 ``.zip`` without ``trusted``.
    """
    folder = Path(run_dir) / "policies"
    paths = {
        side: [inside(folder, n, run_dir, "policy file") for n in names[side]] for side in SIDES
    }
    for path in (p for side in SIDES for p in paths[side]):
        if not path.is_file():
            raise ValueError(f"policy file {path}, listed in {run_dir / STATE}, does not exist")
        if path.suffix == ".zip":
            require_trusted(path, trusted)
    models: dict[str, list[BaseAlgorithm]] = {}
    for side in SIDES:
        with entries[side].make(**env_kwargs) as env:
            models[side] = [
                load_model(path, env, run_dir, device, kwargs, algo, trusted)
                for path in paths[side]
            ]
    return models


def _read_state(path: Path) -> dict[str, Any]:
    state = read_json(path, "self-play state")
    pops = state.get("populations")
    if (
        not isinstance(pops, dict)
        or not all(isinstance(pops.get(side), list) for side in SIDES)
        or not isinstance(state.get("history"), list)
    ):
        raise ValueError(f"self-play state {path} is corrupt: no populations or history")
    return state


def run_selfplay(cfg: GameConfig, report: Callable[[str], None] | None = print) -> SelfPlayResult:
    """Run ``cfg.method`` for ``cfg.iterations`` iterations and write the run folder.

    Every option is checked (and a learner built) before a new run's folder is created; a new
    run that fails or is stopped before its first iteration finishes leaves no folder.
    SIGINT/SIGTERM stop after the current best response's step (the unfinished iteration is
    dropped; :attr:`SelfPlayResult.interrupted` names the signal); a second one raises
    :class:`agents.interrupt.Aborted`. The previous signal handlers are restored.

    Args:
        cfg: The game command's settings.
        report: Called with one line per iteration, and on resuming (None: silent).

    Raises:
        ValueError: For an env that is not a registered two-player game, an unknown method,
            scenario or algorithm (listing the valid names), a repeated game (``rounds > 1``),
            an env option the env does not take, a device not present, nothing to resume, a
            corrupt state or policy file or one outside the run folder, or a resume whose
            options differ.
        UntrustedCheckpointError: For pickle-based policies without
            ``cfg.run.trust_checkpoint``.
        FileExistsError: When a new run's folder exists.
    """
    say = report or (lambda line: None)
    if cfg.method not in METHODS:
        raise ValueError(f"unknown method {cfg.method!r}; valid methods: {', '.join(METHODS)}")
    if cfg.env not in game_names():
        raise ValueError(f"unknown game {cfg.env!r}; valid games: {', '.join(game_names())}")
    check_device_available(cfg.run.device)
    entries = {side: get(cfg.env, side) for side in SIDES}
    algo = entries["attacker"].algorithm(cfg.algo)
    kwargs = algo_kwargs(algo, cfg.hp)
    hyperparameters = resolved_hyperparameters(algo, cfg.hp)
    env_kwargs = entries["attacker"].env_kwargs(cfg.scenario, **parse_env_kwargs(cfg.env_kwargs))
    check_env_kwargs(entries["attacker"].gym_id, env_kwargs)
    env = make_env(lambda: entries["attacker"].make(**env_kwargs), entries["attacker"].gym_id)
    with env:
        reference = entries["attacker"].reference_of(env)
        n = {side: int(env.unwrapped.parallel.action_space(side).n) for side in SIDES}
        build_model(algo, env, kwargs, cfg.run.seed, cfg.run.device)  # SB3 checks the options
    if reference is None or not reference.is_game:
        raise ValueError(f"{cfg.env} with {env_kwargs} is not a one-shot matrix game")
    L, value = reference.matrix_game(), reference.value  # the uninformed Bayesian game: L̄
    given = config_dict(cfg)
    trusted = cfg.run.trust_checkpoint

    with ExitStack() as stack:
        state: dict[str, Any] = {"populations": {"attacker": [], "defender": []}, "history": []}
        if cfg.run.resume:
            run_dir = resume_dir(cfg.run.runs_root, cfg.run.run_dir, game_prefix(cfg), STATE)
            stack.enter_context(run_lock(run_dir))
            saved = read_json(run_dir / "config.json", "run config")
            check_resumable(saved.get("config", {}), given, run_dir)
            state = _read_state(run_dir / STATE)
            check_not_shorter(
                "iterations", cfg.iterations, len(state["history"]), saved.get("config", {}),
                run_dir, "iterations",
            )  # fmt: skip
            names = policy_names(state)
            models = load_policies(
                run_dir, names, entries, env_kwargs, algo, kwargs, cfg.run.device, trusted
            )
            for stale in remove_stale_temp_files(run_dir):
                say(f"removed a temporary file left by an interrupted write: {stale}")
            say(f"resuming {run_dir} after iteration {len(state['history'])}")
        else:
            run_dir = new_run_dir(cfg.run.runs_root, cfg.run.run_dir, game_prefix(cfg))
            run_dir.mkdir(parents=True)
            stack.enter_context(removed_unless(run_dir, STATE))
            stack.enter_context(run_lock(run_dir))
            names = {side: [] for side in SIDES}
            models = {side: [] for side in SIDES}
        write_json(
            run_dir / "config.json",
            {
                "command": "game",
                "config": given,
                "resolved": {
                    "algo": algo,
                    "env_kwargs": env_kwargs,
                    "hyperparameters": hyperparameters,
                    "reference": {"name": reference.name, "value": value},
                },
            },
        )
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        stop = stack.enter_context(stop_on_signals())
        history = _iterate(
            cfg, run_dir, state, names, models, entries, env_kwargs, algo, kwargs,
            hyperparameters, L, value, n, stop, report,
        )  # fmt: skip
        if not history:  # stopped before the first iteration finished
            if not cfg.run.resume:
                stack.close()  # release the lock before removing the folder
                shutil.rmtree(run_dir, ignore_errors=True)
            return SelfPlayResult(
                run_dir, cfg.method, np.zeros(0), np.zeros(0), value, [], interrupted=stop.signum
            )
        x, y = np.array(history[-1]["x"]), np.array(history[-1]["y"])
        pops = state["populations"]
        train_seconds = history[-1]["train_seconds"]
        evaluations = _final_evaluations(entries, env_kwargs, reference, x, y, cfg)
        write_json(
            run_dir / "scores.json",
            {
                "method": cfg.method,
                "value": value,
                "x": x.tolist(),
                "y": y.tolist(),
                "final": {k: history[-1][k] for k in ("defender", "attacker", "nash_conv")},
                "relative_nash_conv": history[-1]["relative_nash_conv"],
                "iterations": len(history),
                "timesteps": history[-1]["timesteps"],
                "train_seconds": train_seconds,
                "interrupted": stop.signum,
                "evaluations": {k: v.to_dict() for k, v in evaluations.items()},
            },
        )
        exploitability_curve(
            run_dir / "learning_curve.png",
            history,
            value,
            f"{cfg.method.upper()} ({algo} best responses) on {cfg.env} ({env_kwargs['scenario']})",
        )
        return SelfPlayResult(
            run_dir,
            cfg.method,
            x,
            y,
            value,
            history,
            evaluations,
            pops,
            train_seconds,
            interrupted=stop.signum,
        )


def _iterate(
    cfg: GameConfig,
    run_dir: Path,
    state: dict[str, Any],
    names: dict[str, list[str]],
    models: dict[str, list[BaseAlgorithm]],
    entries: dict[str, Trainable],
    env_kwargs: dict[str, Any],
    algo: str,
    kwargs: dict[str, Any],
    hyperparameters: dict[str, Any],
    L: np.ndarray,
    value: float,
    n: dict[str, int],
    stop: StopRequest,
    report: Callable[[str], None] | None,
) -> list[dict[str, Any]]:
    """The iterations from the state's last one to ``cfg.iterations`` (or a stop request).

    After each finished iteration its policies are saved and ``state.json`` is rewritten
    (atomically, last). Returns the history of all finished iterations.
    """
    policies_dir = run_dir / "policies"
    pops: dict[str, list[int]] = state["populations"]
    meta = np.array(state.get("meta_payoff", np.zeros((0, 0))), dtype=np.float64)
    meta = meta.reshape(len(pops["defender"]), len(pops["attacker"]))
    history: list[dict[str, Any]] = state["history"]
    x = np.array(state.get("x", np.full(n["defender"], 1.0 / n["defender"])))
    y = np.array(state.get("y", np.full(n["attacker"], 1.0 / n["attacker"])))
    seconds0 = float(state.get("train_seconds", 0.0))
    start = time.perf_counter()
    tb = make_logger(run_dir / "tb", purge_from=len(history) + 1 if history else None)
    callback = StopTrainingCallback(stop)

    iterations = range(len(history) + 1, cfg.iterations + 1)
    if cfg.run.progress_bar:
        from tqdm.auto import tqdm

        iterations = tqdm(iterations, desc=f"{cfg.method} on {cfg.env}", unit="iter")
    for it in iterations:
        if stop.requested:
            break
        opponents = {"attacker": x, "defender": y}  # each side answers the other's mix
        new: dict[str, tuple[BaseAlgorithm, int]] = {}
        for s, side in enumerate(SIDES):
            new[side] = learn_best_response(
                entries[side],
                env_kwargs,
                opponents[side],
                algo,
                kwargs,
                cfg.steps_per_iteration,
                derived_seed(cfg.run.seed, 1000 * it + s),
                cfg.run.device,
                run_dir / "tb" / f"{side}_br_{it:03d}",
                callback,
            )
            if stop.requested:
                break
        if stop.requested:  # the unfinished iteration is dropped
            break
        for side in SIDES:
            model, action = new[side]
            path = policies_dir / f"{side}_{len(pops[side])}.json"
            names[side].append(save_model(model, path, algo, hyperparameters).name)
            models[side].append(model)
            pops[side].append(action)
        # how far each learned response is from an exact best response to the mix it answered
        gap_att = float((x @ L).max() - (x @ L)[pops["attacker"][-1]])
        gap_def = float((L @ y)[pops["defender"][-1]] - (L @ y).min())

        if cfg.method == "psro":
            meta = _grow_meta(meta, models, entries["attacker"], env_kwargs, cfg.run.seed)
        x, y = current_mixes(cfg.method, pops, n, meta)

        e = exploitability(L, x, y, value)
        rec = {
            "iteration": it,
            "timesteps": 2 * it * cfg.steps_per_iteration,
            "train_seconds": round(seconds0 + time.perf_counter() - start, 3),
            "defender": e.defender,
            "attacker": e.attacker,
            "nash_conv": e.nash_conv,
            "relative_nash_conv": e.nash_conv / abs(value),
            "br_attacker": pops["attacker"][-1],
            "br_defender": pops["defender"][-1],
            "br_gap_attacker": gap_att,
            "br_gap_defender": gap_def,
            "x": x.tolist(),
            "y": y.tolist(),
        }
        history.append(rec)
        for key in ("defender", "attacker", "nash_conv", "relative_nash_conv"):
            tb.record(f"selfplay/{key}", rec[key])
        tb.dump(it)
        write_json(
            run_dir / STATE,
            {
                "populations": pops,
                "policies": names,
                "meta_payoff": meta.tolist(),
                "history": history,
                "x": x.tolist(),
                "y": y.tolist(),
                "train_seconds": rec["train_seconds"],
            },
        )
        if report is not None:
            report(_report_line(rec))
    tb.close()
    return history


def _grow_meta(
    meta: np.ndarray,
    models: dict[str, list[BaseAlgorithm]],
    attacker_entry: Trainable,
    env_kwargs: dict[str, Any],
    seed: int,
) -> np.ndarray:
    """Extend the empirical meta-payoff (defender rows, attacker columns) to the new policies.

    Only the new row and column are played (one episode per pair: the payoff of two
    deterministic policies in the expected-dynamics game is exact; sampled dynamics would
    need more).
    """
    m, k = len(models["defender"]), len(models["attacker"])
    out = np.zeros((m, k))
    out[: meta.shape[0], : meta.shape[1]] = meta
    for i in range(m):
        for j in range(k):
            if i < meta.shape[0] and j < meta.shape[1]:
                continue
            out[i, j] = empirical_payoff(
                models["attacker"][j], models["defender"][i], attacker_entry, env_kwargs, 1, seed
            )
    return out


def _final_evaluations(
    entries: dict[str, Trainable],
    env_kwargs: dict[str, Any],
    reference: Reference,
    x: np.ndarray,
    y: np.ndarray,
    cfg: GameConfig,
) -> dict[str, Evaluation]:
    """Each side's learned mix and LP equilibrium mix, played against the other learned mix."""
    seed = derived_seed(cfg.run.seed, 20_000)
    x_eq, y_eq, _ = solve_zero_sum(reference.payoff)
    rows = {}
    for label, side, probs, other in (
        ("attacker mix (learned)", "attacker", y, x),
        ("attacker LP equilibrium", "attacker", y_eq, x),
        ("defender mix (learned)", "defender", x, y),
        ("defender LP equilibrium", "defender", x_eq, y),
    ):
        entry = entries[side]
        with entry.make(
            opponent=MixedStrategyPolicy(other, seed=derived_seed(seed, 1)), **env_kwargs
        ) as env:
            rows[label] = evaluate(
                MixedStrategyPolicy(probs, seed=seed),
                env,
                cfg.final_eval_episodes,
                seed,
                entry.reference_of(env),
            )
    return rows
