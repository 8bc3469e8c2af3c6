"""Equilibrium finding with learned best responses on a one-shot two-player game (SB3).

The loop is :func:`agents.population.run_population` (IBR, FSP, PSRO: see there) with
:class:`SB3Oracle`: each iteration trains a fresh SB3 learner (PPO, A2C or DQN) for each side
on its Gymnasium view against the other side's current mixed strategy (a
:class:`~fdia_env.envs.opponents.FixedMix`). After every iteration the exploitability of the
current pair is measured exactly on ``baselines.game.payoff_matrix``
(:func:`baselines.game.exploitability`). In the typed sensor game (``--env-kwargs types
'["independent","dependent"]' priors '[0.5,0.5]' attacker_model uninformed``) the matrix is the
Bayesian game's ``L̄ = Σ_s p_s L_s`` and the meta-game's payoffs are exact averages over
nature's draw; the informed-attacker game is not a matrix game over the attacker's actions and
is refused.

The run folder's lifecycle (lock, option check, resume, signals, scores) is
:mod:`agents.lifecycle`'s. The learned policies are saved as ``policies/<side>_<k>.pt`` /
``.json`` in the format of :mod:`agents.checkpoint` (tensors and JSON; loading unpickles
nothing) and ``state.json`` holds the iterations done, so ``--resume`` continues after the last
finished iteration. Older runs' ``policies/*.zip`` load only with ``--trust-checkpoint``.
SIGINT/SIGTERM stop after the best response being trained (the unfinished iteration is dropped)
and the scores of the finished iterations are written.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
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
    GAME_EXPECTED_REWARDS,
    TORCH_PPO,
    GameConfig,
    Hyperparameters,
    algo_kwargs,
    check_device_available,
    resolve_device,
    resolved_hyperparameters,
    scenario_defaults,
    with_defaults,
)
from agents.evaluate import Evaluation, evaluate
from agents.interrupt import StopRequest, StopTrainingCallback
from agents.lifecycle import game_scores, open_run, tensorboard
from agents.plots import exploitability_curve
from agents.population import (
    METHODS,
    SIDES,
    BestResponse,
    ConstantPolicy,
    ExactOracle,
    LearnedOracle,
    MatrixGame,
    Oracle,
    PopulationState,
    at_fixed_point,
    initial_action,
    report_line,
    run_population,
)
from agents.registry import Reference, Trainable, equilibrium, game_names, get
from agents.runs import run_prefix, write_json
from agents.seeding import derived_seed, seed_everything
from agents.training import (
    NormalizedReward,
    RunSetup,
    check_env_kwargs,
    env_thunk,
    make_env,
    run_setup,
    saved_env_kwargs,
    saved_hyperparameters,
    say_kept,
)
from baselines.game import MixedStrategyPolicy
from fdia_env.envs.opponents import FixedMix

if TYPE_CHECKING:
    from agents.torch_ppo import TorchPPOConfig

STATE = "state.json"  # a game run folder that --resume can continue has it
EXACT = "exact"  # --algo exact: the exact best response on the payoff matrix
GAME_NUM_ENVS = 64  # torch-ppo best responses: members of the torch vector env
EXPECTED_MAX_SUPPORT = 64  # expected rewards: at most this many env copies, else sampled


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
        task_score: A ``--task`` run's :class:`agents.bench.score.Score` of its player's final
            mix on the task (scores.json's ``task``), else None.
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
    task_score: Any = None


class ExpectedOpponentEnv(gym.Env):
    """A side's Gymnasium view against a mixed opponent, paid the mix's expected reward.

    One copy of the view per pure strategy in the support of ``opponent`` (each copy's opponent
    plays that strategy, :class:`~agents.population.ConstantPolicy`). Every action of the
    learner is played in all copies, and the reward is the probability-weighted sum of the
    copies' rewards: the exact expectation over the opponent's draw, where a view with a
    sampled opponent (:class:`~fdia_env.envs.opponents.FixedMix`) pays one draw of it. The
    expected return of every policy is the same in both, so the best response is the same; only
    the learner's reward noise from the opponent's draw is gone. It costs one env step per
    support strategy.

    In the one-shot game the learner's observations and masks do not depend on the opponent's
    action (it sees its own features and its own picks), so the copies stay in lockstep; every
    reset seeds all copies alike (nature's draw of a typed game is then the same in each). In
    the sequential format a round ends once both players have stopped, so a copy whose
    opponent builds a shorter subset ends first: the learner has stopped by then (its only legal
    action is stop in every copy), the ended copy is left alone, and the episode ends with the
    last copy.

    Args:
        gym_id: The side's registered view (``fdia_env/SensorGameDefender-v0``, ...).
        env_kwargs: The env's options.
        opponent: (n,) the other side's mix over its actions.

    Raises:
        ValueError: For an ``opponent`` that is not a 1-D mix of probabilities.
    """

    def __init__(self, gym_id: str, env_kwargs: dict[str, Any], opponent: np.ndarray) -> None:
        probs = np.asarray(opponent, dtype=np.float64)
        if probs.ndim != 1 or not np.all(np.isfinite(probs)) or probs.min() < 0 or probs.sum() <= 0:
            raise ValueError(f"opponent must be a 1-D mix of probabilities, got {opponent!r}")
        support = np.flatnonzero(probs > 0)
        self.weights = probs[support] / probs[support].sum()
        self.copies = [
            gym.make(gym_id, opponent=ConstantPolicy(int(a)), **env_kwargs) for a in support
        ]
        self.observation_space = self.copies[0].observation_space
        self.action_space = self.copies[0].action_space
        self._running = [True] * len(self.copies)
        self._return = 0.0
        self._first: int | None = None
        self.values: dict[int, float] = {}
        """The exact expected return of every pure strategy (subset index) the learner played."""

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every copy with one seed (drawn from this env's generator when None)."""
        super().reset(seed=seed)
        shared = int(self.np_random.integers(2**31 - 1))
        outs = [env.reset(seed=shared, options=options) for env in self.copies]
        self._running = [True] * len(self.copies)
        self._return, self._first = 0.0, None
        return outs[0]

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Play ``action`` in every running copy; the reward is their probability-weighted sum.

        Raises:
            RuntimeError: After the episode ended (every copy has).
        """
        if not any(self._running):
            raise RuntimeError("the episode has ended: call reset()")
        reward, truncated, last = 0.0, False, None
        for k, env in enumerate(self.copies):
            if not self._running[k]:
                continue
            obs, r, term, trunc, info = env.step(action)
            reward += self.weights[k] * float(r)
            truncated = truncated or bool(trunc)
            self._running[k] = not (term or trunc)
            if last is None or self._running[k]:
                last = (obs, info)
        assert last is not None  # a running copy was stepped
        ended = not any(self._running)
        self._return += reward
        if self._first is None:
            self._first = int(np.asarray(action).reshape(-1)[0])
        if ended:
            self.values[self._played()] = self._return
        return last[0], reward, ended and not truncated, ended and truncated, last[1]

    def _played(self) -> int:
        """The learner's pure strategy of the episode: its subset (its first action if one-shot)."""
        view = self.copies[0].unwrapped
        subsets = getattr(view, "first_subsets", None)  # the sequential format's view
        if subsets is not None:
            return int(subsets[-1])
        assert self._first is not None
        return self._first

    def value_of(self, strategy: int) -> float:
        """The exact expected return of the learner's pure strategy (one episode played).

        In the sequential format the subset is built one pick per decision, then stop (and wait,
        stop, until every copy's round has ended).
        """
        from fdia_env.envs.sequential import STOP, subset_actions

        view = self.copies[0].unwrapped
        if getattr(view, "first_subsets", None) is None:
            actions = [int(strategy)]
        else:
            subset = view.parallel.models[view.agent].subsets[int(strategy)]
            picks = subset_actions(view.parallel, view.agent, subset)
            actions = [*picks, *[STOP] * (2 * (view.parallel.M + 1))]
        self.reset(seed=0)
        for action in actions:
            *_, terminated, truncated, _ = self.step(action)
            if terminated or truncated:
                return self.values[int(strategy)]
        raise RuntimeError(f"strategy {strategy} did not end its episode")

    def best_strategy(self, candidate: int) -> int:
        """``candidate`` unless a strategy played so far has a higher expected return."""
        value = self.values[candidate] if candidate in self.values else self.value_of(candidate)
        best = max(self.values, key=lambda a: self.values[a])
        return best if self.values[best] > value else int(candidate)

    def action_masks(self) -> np.ndarray:
        """The learner's legal actions now (the same in every running copy)."""
        k = next((k for k, running in enumerate(self._running) if running), 0)
        return self.copies[k].unwrapped.action_masks()

    def close(self) -> None:
        """Close every copy."""
        for env in self.copies:
            env.close()


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
    reward_scale: float | None = None,
    expected: bool = False,
) -> tuple[BaseAlgorithm, int]:
    """A fresh ``algo`` learner trained against the fixed mix ``opponent``, and its action.

    The learner plays ``entry``'s side; the action is its pure strategy (:func:`initial_action`).
    ``callback`` may end training early (as :class:`~agents.interrupt.StopTrainingCallback`).
    ``reward_scale``: train on the rewards divided by it (e.g. the game value's size).
    ``expected``: pay the expected reward over the mix (:class:`ExpectedOpponentEnv`) instead
    of one draw of it per episode, where the mix has at most :data:`EXPECTED_MAX_SUPPORT`
    strategies (a wider one, e.g. the uniform mix of PSRO's first iteration, is sampled).
    There every episode's return is the exact value of the subset the learner built, so in the
    sequential format (whose meta-game plays each side's pure strategy,
    :func:`agents.population.grow_meta`) the answer is the best subset the learner played
    during training where it beats the final policy's own (:meth:`ExpectedOpponentEnv.
    best_strategy`); the saved policy is the final one.
    """
    seed_everything(seed)
    if expected and np.count_nonzero(opponent) <= EXPECTED_MAX_SUPPORT:

        def make() -> gym.Env:
            env: gym.Env = Monitor(ExpectedOpponentEnv(entry.gym_id, env_kwargs, opponent))
            return env if reward_scale is None else NormalizedReward(env, 0.0, reward_scale)

    else:
        make = env_thunk(
            entry.gym_id,
            env_kwargs,
            lambda: FixedMix(opponent, seed=derived_seed(seed, 1)),
            monitor=True,
            reward=None if reward_scale is None else (0.0, reward_scale),
        )
    vec_env = DummyVecEnv([make])
    model = build_model(algo, vec_env, kwargs, seed, device)
    if tb_dir is not None:  # a resumed iteration replaces the unfinished one's events
        model.set_logger(tensorboard(tb_dir, purge_from=0))
    model.learn(steps, callback=callback)
    action = initial_action(model, entry, env_kwargs)
    inner = vec_env.envs[0].unwrapped
    if isinstance(inner, ExpectedOpponentEnv) and env_kwargs.get("action") == "sequential":
        action = inner.best_strategy(action)  # the best subset the learner played
    vec_env.close()
    if tb_dir is not None:
        model.logger.close()
    return model, action


def game_algo(cfg: GameConfig) -> str:
    """The best-response oracle ``--algo`` names: ``exact``, ``torch-ppo`` or an SB3 algorithm.

    Raises:
        ValueError: For an algorithm that does not apply (listing the valid ones).
    """
    if cfg.task is not None:  # exact by default
        from agents.game_task_runs import game_task_setup

        return game_task_setup(cfg).algo
    if isinstance(cfg.algo, str) and cfg.algo.strip().lower() == EXACT:
        return EXACT
    return game_setup(cfg).algo


def game_setup(cfg: GameConfig) -> RunSetup:
    """The game's options resolved with its scenario's defaults (:func:`run_setup`).

    With ``--task``: the task's options as they are (no preset applied), the learners' defaults
    from the scenario's table where its conditions hold.
    """
    if cfg.task is not None:
        from agents.game_task_runs import game_task_setup

        task = game_task_setup(cfg)
        entry = task.entries["attacker"]
        name = entry.default_algorithm if task.algo == EXACT else task.algo
        defaults = scenario_defaults(entry.env, task.scenario, task.env_kwargs)
        normalize = cfg.normalize_reward
        if normalize is None:
            normalize = defaults.normalize_reward
        hp = with_defaults(name, cfg.hp, defaults)
        return RunSetup(entry, name, task.env_kwargs, hp, bool(normalize))
    algo = None if isinstance(cfg.algo, str) and cfg.algo.strip().lower() == EXACT else cfg.algo
    return run_setup(
        cfg.env, "attacker", cfg.scenario, cfg.env_kwargs, algo, cfg.hp, cfg.normalize_reward
    )


def expected_rewards(cfg: GameConfig, algo: str) -> bool:
    """Whether the best responses train on the expected reward over the other side's mix.

    ``cfg.expected_rewards``, else the scenario's default (:data:`GAME_EXPECTED_REWARDS`); an
    SB3 learner's option only.

    Raises:
        ValueError: For ``--expected-rewards`` with ``--algo exact`` or ``torch-ppo``.
    """
    if algo in (EXACT, TORCH_PPO):
        if cfg.expected_rewards:
            raise ValueError(
                f"--expected-rewards applies to SB3 best responses (PPO, A2C, DQN, "
                f"MaskablePPO), not --algo {algo}"
            )
        return False
    if cfg.expected_rewards is not None:
        return cfg.expected_rewards
    if cfg.task is not None:
        from fdia_env.tasks import get as get_task

        return get_task(cfg.task).env_kwargs.get("scenario") in GAME_EXPECTED_REWARDS
    return cfg.scenario in GAME_EXPECTED_REWARDS


def game_prefix(cfg: GameConfig) -> str:
    """Run folder name without its time: ``<env>-<method>-<algo>-s<seed>``.

    A ``--task`` run's env part is the task's: ``task-sensor-game-ch5-game-attacker-v0``.
    """
    if cfg.task is not None:
        from agents.task_runs import run_env_name

        return run_prefix(f"{run_env_name(cfg.task)}-{cfg.method}", game_algo(cfg), cfg.run.seed)
    return run_prefix(f"{cfg.env}-{cfg.method}", game_algo(cfg), cfg.run.seed)


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
        with entries[side].make_resolved(env_kwargs) as env:
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
    task = None
    if cfg.task is not None:  # the task's game, as the task builds it
        from agents.game_task_runs import game_task_setup

        task_setup = game_task_setup(cfg)
        task, entries = task_setup.task, dict(task_setup.entries)
    elif cfg.env not in game_names():
        raise ValueError(f"unknown game {cfg.env!r}; valid games: {', '.join(game_names())}")
    else:
        entries = {side: get(cfg.env, side) for side in SIDES}
    check_device_available(cfg.run.device)
    algo = game_algo(cfg)
    setup = game_setup(cfg)
    kwargs, hyperparameters, torch_config = _learner_options(cfg, algo, setup.hp)
    env_kwargs = setup.env_kwargs
    if task is not None and algo == EXACT:
        from agents.game_task_runs import is_informed

        if is_informed(task):  # no matrix game: exact answers per type (agents.informed_game)
            from agents.game_task_runs import score_game_run
            from agents.informed_game import run_informed_task

            run = run_informed_task(
                cfg, entries, env_kwargs, game_prefix(cfg), STATE, SelfPlayResult, report
            )
            return score_game_run(task, run)
    reference = _game_reference(cfg, entries, algo, kwargs, env_kwargs)
    expected = expected_rewards(cfg, algo)
    trusted = cfg.run.trust_checkpoint

    with ExitStack() as stack:
        state: dict[str, Any] = {"populations": {"attacker": [], "defender": []}, "history": []}
        run = open_run(cfg, stack, game_prefix(cfg), STATE, report, fresh=True)
        run_dir = run.path
        # a resume plays the game its run was resolved with (train.py's per-scenario defaults
        # change between versions), as the attacker and defender drivers do
        saved = saved_env_kwargs(env_kwargs, run.saved_resolved, say)
        if algo != EXACT:  # and its learners train with the run's own hyperparameters
            hp = saved_hyperparameters(
                algo, setup.hp, run.saved_resolved, say, run_dir / "config.json"
            )
            if hp != setup.hp:
                kwargs, hyperparameters, torch_config = _learner_options(cfg, algo, hp)
        if saved != env_kwargs:
            env_kwargs = saved
            reference = _game_reference(cfg, entries, algo, kwargs, env_kwargs)
        L, value = reference.matrix_game(), reference.value  # the uninformed Bayesian game: L̄
        # each side's pure strategies: the subsets (also in the sequential format, whose
        # actions are single sensors)
        n = {"defender": int(L.shape[0]), "attacker": int(L.shape[1])}
        scale = abs(value) if setup.normalize_reward and algo not in (EXACT, TORCH_PPO) else None
        resolved = run.saved_resolved
        for name, today in (("expected_rewards", expected), ("reward_scale", scale)):
            if name in resolved and resolved[name] != today:  # a resume keeps the run's own
                say_kept(say, name.replace("_", " "), resolved[name], today)
        expected = resolved.get("expected_rewards", expected)
        scale = resolved.get("reward_scale", scale)
        if run.checkpointed:
            state = _read_state(run_dir / STATE)
            run.check_not_shorter(
                "iterations", cfg.n_iterations, len(state["history"]), "iterations"
            )
            names = policy_names(state)
            if algo == EXACT:
                models = {s: [ConstantPolicy(a) for a in state["populations"][s]] for s in SIDES}
            elif algo == TORCH_PPO:
                models = _load_torch_policies(run_dir, names, cfg.run.device)
            else:
                models = load_policies(
                    run_dir, names, entries, env_kwargs, algo, kwargs, cfg.run.device, trusted
                )
            say(f"resuming {run_dir} after iteration {len(state['history'])}")
        else:  # a new run, or one stopped before its first iteration's state: from iteration 0
            if run.resumed:
                say(run.restart_note())
            run.begin()
            names = {side: [] for side in SIDES}
            models = {side: [] for side in SIDES}
        if task is not None:
            from agents.game_task_runs import task_resolved

            on_task = task_resolved(task)  # the task, its player's view and its options
        run.write_config(
            "game",
            cfg,
            {
                "algo": algo,
                "env_kwargs": env_kwargs,
                "hyperparameters": hyperparameters,
                "reward_scale": scale,
                "expected_rewards": expected,
                "reference": {"name": reference.name, "value": value},
                **({} if task is None else on_task),
            },
        )
        seed_everything(cfg.run.seed, cfg.run.torch_threads)
        stop = run.watch_signals()
        # a --task run's exact answers: PSRO's meta-game from the exact payoffs (double oracle)
        exact_meta = task is not None and algo == EXACT
        game = MatrixGame(entries, env_kwargs, L, value, exact_meta=exact_meta)
        oracle: Oracle
        if algo == EXACT:
            oracle = ExactOracle(L)
        elif algo == TORCH_PPO:
            oracle = TorchPPOOracle(cfg, run_dir, entries, env_kwargs, torch_config, stop)
        else:
            oracle = SB3Oracle(
                cfg, run_dir, entries, env_kwargs, algo, kwargs, hyperparameters, stop, scale,
                expected,
            )  # fmt: skip
        loop = _population_state(state, names, models, n)
        # --task's double oracle: to its fixed point (each iteration before it adds a strategy)
        iterations = cfg.n_iterations
        if cfg.converges and cfg.iterations is None:
            iterations = n["defender"] + n["attacker"]
        history = _iterate(cfg, run_dir, loop, oracle, game, stop, report, iterations)
        if not history:  # stopped before the first iteration finished
            run.discard()  # a new run's folder (the lock released first)
            return SelfPlayResult(
                run_dir, cfg.method, np.zeros(0), np.zeros(0), value, [], interrupted=stop.signum
            )
        x, y = np.array(history[-1]["x"]), np.array(history[-1]["y"])
        pops = loop.actions
        train_seconds = history[-1]["train_seconds"]
        evaluations = _final_evaluations(entries, env_kwargs, reference, x, y, cfg)
        run.write_scores(
            game_scores(cfg.method, value, x, y, history, history[-1]["timesteps"], train_seconds),
            evaluations,
        )
        on = f"task {task.name}" if task is not None else cfg.env
        exploitability_curve(
            run_dir / "learning_curve.png",
            history,
            value,
            f"{cfg.method.upper()} ({algo} best responses) on {on} ({env_kwargs['scenario']})",
        )
        result = SelfPlayResult(
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
        if task is not None:  # scored as python -m agents.bench score scores the folder
            from agents.game_task_runs import score_game_run

            return score_game_run(task, result)
        return result


def _game_reference(
    cfg: GameConfig, entries: dict[str, Any], algo: str, kwargs: Any, env_kwargs: dict[str, Any]
) -> Any:
    """The game's reference (its payoff matrix), its options checked, as the driver starts.

    Raises:
        ValueError: For env options the env rejects, learner options SB3 rejects, or a game
            that is not a one-shot matrix game.
    """
    attacker = entries["attacker"]
    check_env_kwargs(attacker.gym_id, env_kwargs)
    env = make_env(lambda: attacker.make_resolved(env_kwargs), attacker.gym_id)
    with env:
        reference = attacker.reference_of(env)
        if algo not in (EXACT, TORCH_PPO):  # SB3 checks the options when it builds a model
            build_model(algo, env, kwargs, cfg.run.seed, cfg.run.device)
    if reference is None or not reference.is_game:
        raise ValueError(f"{cfg.env} with {env_kwargs} is not a one-shot matrix game")
    reference.matrix_game()  # raises for the informed-attacker Bayesian game
    return reference


def _learner_options(
    cfg: GameConfig, algo: str, hp: Hyperparameters
) -> tuple[dict[str, Any], dict[str, Any], TorchPPOConfig | None]:
    """The SB3 kwargs, the resolved hyperparameters and torch-ppo's config of ``algo``.

    Raises:
        ValueError: For a hyperparameter given with ``--algo exact`` (nothing learns), or one
            that does not apply to the learner.
    """
    if algo == EXACT:
        given = [f.name for f in dataclasses.fields(cfg.hp) if getattr(cfg.hp, f.name) is not None]
        if given:
            raise ValueError(
                f"--algo exact answers with the exact best response on the payoff matrix: "
                f"{', '.join('--' + g.replace('_', '-') for g in given)} do(es) not apply"
            )
        return {}, {}, None
    if algo == TORCH_PPO:
        from agents.torch_ppo import TorchPPOConfig

        hyperparameters = resolved_hyperparameters(TORCH_PPO, hp)
        num_envs = min(GAME_NUM_ENVS, cfg.steps_per_iteration)
        try:
            config = TorchPPOConfig.from_hyperparameters(
                hyperparameters, cfg.steps_per_iteration, num_envs
            )
        except (TypeError, ValueError) as exc:
            raise ValueError(f"--algo torch-ppo: {exc}") from None
        return {}, hyperparameters, config
    return algo_kwargs(algo, hp), resolved_hyperparameters(algo, hp), None


def _load_torch_policies(
    run_dir: Path, names: dict[str, list[str]], device: str
) -> dict[str, list[Any]]:
    """A torch-ppo game's saved policies (tensors and JSON, :func:`~agents.torch_ppo.load_policy`).

    Raises:
        ValueError: For a file outside the run folder, missing, corrupt or tampered with.
    """
    from agents.torch_ppo import load_policy

    folder = Path(run_dir) / "policies"
    return {
        side: [
            load_policy(inside(folder, name, run_dir, "policy file"), run_dir, device)
            for name in names[side]
        ]
        for side in SIDES
    }


@dataclass
class TorchPPOOracle(LearnedOracle):
    """Best responses learned by torch-ppo on the device (the ``torch-ppo`` oracle).

    Each answer trains a fresh :func:`~agents.torch_ppo.train_torch_ppo` policy for
    ``--steps-per-iteration`` env steps on the side's torch vector env (B = min(64, steps)
    members), the other side's mix drawn per member as its fixed opponent; it is saved as
    ``policies/<side>_<k>.json`` / ``.pt`` (tensors only). A stop request ends training after
    the current PPO iteration and drops the answer.
    """

    config: TorchPPOConfig
    stop: StopRequest

    def __post_init__(self) -> None:
        self.device = resolve_device(self.cfg.run.device)

    def learn(self, side: str, opponent: np.ndarray, iteration: int) -> BestResponse | None:
        """A fresh torch-ppo policy's answer to ``opponent``, or None if a stop cut it short."""
        from agents.torch_ppo import make_torch_env, train_torch_ppo

        entry = self.entries[side]
        seed = self.seed(side, iteration)
        mix = FixedMix(opponent, seed=derived_seed(seed, 1))
        venv = make_torch_env(
            entry.gym_id, self.config.num_envs, self.device, opponent=mix, **self.env_kwargs
        )
        try:
            result = train_torch_ppo(venv, self.config, seed, stop=lambda: self.stop.requested)
        finally:
            venv.close()
        if self.stop.requested:
            return None
        return BestResponse(result.policy, initial_action(result.policy, entry, self.env_kwargs))

    def save(self, side: str, index: int, response: BestResponse) -> str:
        """Save the policy as ``policies/<side>_<index>.json``; returns the file's name."""
        from agents.torch_ppo import save_policy

        return save_policy(response.policy, self.policy_path(side, index), self.config).name


@dataclass
class SB3Oracle(LearnedOracle):
    """Best responses learned by a fresh stable-baselines3 learner each (the ``sb3`` oracle).

    Each answer trains ``algo`` for ``steps`` env steps on the side's Gymnasium view against
    the other side's mix (seed derived from the run's, the iteration and the side; with
    ``expected``, paid the expected reward over the mix, :class:`ExpectedOpponentEnv`), logs to
    ``tb/<side>_br_<iteration>``, and is saved as ``policies/<side>_<k>.json`` / ``.pt``.
    A stop request ends the learner at its next step and drops the answer.
    """

    algo: str
    kwargs: dict[str, Any]
    hyperparameters: dict[str, Any]
    stop: StopRequest
    reward_scale: float | None = None
    expected: bool = False

    def __post_init__(self) -> None:
        self.callback = StopTrainingCallback(self.stop)

    def learn(self, side: str, opponent: np.ndarray, iteration: int) -> BestResponse | None:
        """A fresh learner's answer to ``opponent``, or None if a stop request cut it short."""
        model, action = learn_best_response(
            self.entries[side],
            self.env_kwargs,
            opponent,
            self.algo,
            self.kwargs,
            self.cfg.steps_per_iteration,
            self.seed(side, iteration),
            self.cfg.run.device,
            self.run_dir / "tb" / f"{side}_br_{iteration:03d}",
            self.callback,
            self.reward_scale,
            self.expected,
        )
        return None if self.stop.requested else BestResponse(model, action)

    def save(self, side: str, index: int, response: BestResponse) -> str:
        """Save the model as ``policies/<side>_<index>.json``; returns the file's name."""
        path = self.policy_path(side, index)
        return save_model(response.policy, path, self.algo, self.hyperparameters).name


def _population_state(
    state: dict[str, Any],
    names: dict[str, list[str]],
    models: dict[str, list[BaseAlgorithm]],
    n: dict[str, int],
) -> PopulationState:
    """The loop state of a new run (empty) or of a resumed run's ``state.json``."""
    pops = state["populations"]
    meta = np.array(state.get("meta_payoff", np.zeros((0, 0))), dtype=np.float64)
    return PopulationState(
        pops,
        models,
        names,
        meta.reshape(len(pops["defender"]), len(pops["attacker"])),
        np.array(state.get("x", np.full(n["defender"], 1.0 / n["defender"]))),
        np.array(state.get("y", np.full(n["attacker"], 1.0 / n["attacker"]))),
        state["history"],
        float(state.get("train_seconds", 0.0)),
    )


def _iterate(
    cfg: GameConfig,
    run_dir: Path,
    loop: PopulationState,
    oracle: Oracle,
    game: MatrixGame,
    stop: StopRequest,
    report: Callable[[str], None] | None,
    iterations: int,
) -> list[dict[str, Any]]:
    """The iterations from the state's last one to ``iterations`` (or a stop request).

    A run that :attr:`~agents.config.GameConfig.converges` also stops at the loop's fixed
    point (:func:`~agents.population.at_fixed_point`). After each finished iteration its
    policies are saved and ``state.json`` is rewritten (atomically, last). Returns the history
    of all finished iterations.
    """
    tb = tensorboard(run_dir / "tb", purge_from=len(loop.history) + 1 if loop.history else None)

    def on_iteration(rec: dict[str, Any], state: PopulationState) -> None:
        for key in ("defender", "attacker", "nash_conv", "relative_nash_conv"):
            tb.record(f"selfplay/{key}", rec[key])
        tb.dump(rec["iteration"])
        write_json(
            run_dir / STATE,
            {**state.saved(), "history": state.history, "train_seconds": rec["train_seconds"]},
        )
        if report is not None:
            report(report_line(rec))

    progress = None
    if cfg.run.progress_bar:
        from tqdm.auto import tqdm

        def progress(steps: range) -> Any:
            return tqdm(steps, desc=f"{cfg.method} on {cfg.env}", unit="iter")

    steps = 0 if isinstance(oracle, ExactOracle) else cfg.steps_per_iteration  # exact: none

    def done() -> bool:
        converged = cfg.converges and bool(loop.history)
        return stop.requested or (converged and at_fixed_point(cfg.method, loop.actions))

    history = run_population(
        cfg.method, oracle, game, loop, iterations, cfg.run.seed, steps, done, on_iteration,
        progress,
    )  # fmt: skip
    tb.close()
    return history


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
    x_eq, y_eq, _ = equilibrium(reference.payoff)
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
