"""``detection_learned``: learned players of the detection game against the analytic ones.

At the settings where random thresholds separate from OBDD (ch3-static a² = 10 and 1000,
ch3-tracking a² = 100; table ``detection``), in exact expected dynamics (a one-step game whose
reward is a deterministic function of the two actions, :mod:`baselines.detection.response`):

1. Analytic references under both criteria (``"bayes_cost"``, ``"mse"``): the defender's best
   threshold against the preset attack (p1, the c2-maximising Σ) by a 1-D search, against OBDD's
   α; the attacker's best response (p, Σ) to each analytic detector (OBDD, OBDI, CBD, CSD, and
   the MSE-optimal threshold τ*) by multi-start search over its action box, against the preset
   attack. Each is cross-checked against the env's own reward.
2. A learned attacker (SAC on ``DetectionAttacker-v0``, MSE criterion) against each detector,
   scored against the numerical best response (and random attacks).
3. A learned defender (SAC on ``DetectionDefender-v0``, MSE criterion) scored against τ* and
   OBDD's α (and random thresholds).
4. Learned against learned (ch3-static a² = 1000, MSE): alternating best responses, each side's
   payoff against the other, against its exact best response and its worst case, with OBDD's α
   and the minimax (security) threshold as the analytic counterparts.

Learned rows: 3 seeds, mean ± 95 % CI. A policy of this one-step game is its action at the
(constant) initial observation; learned opponents are fixed to that action.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.evaluate import evaluate
from agents.registry import Reference
from baselines.detection import DETECTORS, DetectionProblem, static_problem, tracking_problem
from baselines.detection.response import (
    DetectionGame,
    best_attack,
    best_threshold,
    minimax_threshold,
)
from experiments.results.common import mean_ci95, write_rows
from experiments.results.detection_learned_report import GAME_SETTING, format_tables, plot
from fdia_env.detection_game_v0 import FixedAction
from fdia_env.envs.single_agent import make_single_agent

MODULE = "fdia_env.detection_game_v0"
SETTINGS = (("ch3-static", 10.0), ("ch3-static", 1000.0), ("ch3-tracking", 100.0))
CRITERIA = ("bayes_cost", "mse")
OPTIMAL = "τ*_MSE"  # the MSE-optimal threshold against the preset attack, as a fixed detector
FIXED_DEFENDERS = (*DETECTORS, OPTIMAL)
# SAC for a one-step bandit: few gradient steps per sample, entropy started low, decaying rate
SAC_KWARGS: dict[str, Any] = {
    "learning_rate": 3e-3,
    "gamma": 1.0,
    "batch_size": 64,
    "buffer_size": 100_000,
    "learning_starts": 250,
    "train_freq": 2,
    "tau": 0.005,
    "ent_coef": "auto_0.1",
    "policy_kwargs": {"net_arch": [64, 64]},
}


@dataclass(frozen=True)
class Budget:
    """How much of the table to run.

    Attributes:
        settings: (scenario, power) pairs.
        seeds: Seeds of the learned rows (offsets from the base seed).
        attacker_steps: SAC steps of a learned attacker.
        defender_steps: SAC steps of a learned defender.
        rounds: Alternating best-response rounds (each: an attacker, then a defender).
        round_steps: SAC steps of each alternating best response.
        random_episodes: Episodes of random play (the baseline of the learned rows).
        starts: Random starts of the attacker's best-response search.
        refine: Best starts refined by Nelder-Mead in that search.
        detectors: Fixed defenders of the attacker's best responses.
        attacker_criteria: Criteria of the attacker's best responses.
        learn_against: Fixed defenders the learned attacker faces (None: every detector where
            the reward depends on the attack).
        minimax_grid: Grid of the minimax-threshold search (0: skipped).
    """

    settings: tuple[tuple[str, float], ...] = SETTINGS
    seeds: int = 3
    attacker_steps: int = 1500
    defender_steps: int = 2000
    rounds: int = 2
    round_steps: int = 1000
    random_episodes: int = 100
    starts: int = 16
    refine: int = 4
    detectors: tuple[str, ...] = FIXED_DEFENDERS
    attacker_criteria: tuple[str, ...] = CRITERIA
    learn_against: tuple[str, ...] | None = None
    minimax_grid: int = 11

    def __post_init__(self) -> None:
        for name in (
            "seeds",
            "attacker_steps",
            "defender_steps",
            "round_steps",
            "random_episodes",
            "starts",
            "refine",
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if isinstance(self.rounds, bool) or not isinstance(self.rounds, int) or self.rounds < 0:
            raise ValueError(f"rounds must be an integer >= 0, got {self.rounds!r}")
        grid = self.minimax_grid
        if isinstance(grid, bool) or not isinstance(grid, int) or grid < 0 or grid == 1:
            raise ValueError(f"minimax_grid must be 0 (skip) or an integer >= 2, got {grid!r}")
        unknown = [
            d for d in (*self.detectors, *(self.learn_against or ())) if d not in FIXED_DEFENDERS
        ]
        unknown += [c for c in self.attacker_criteria if c not in CRITERIA]
        if unknown:
            raise ValueError(
                f"detectors and learn_against must be among {list(FIXED_DEFENDERS)}, "
                f"attacker_criteria among {list(CRITERIA)}; got {unknown}"
            )


QUICK = Budget(
    settings=(GAME_SETTING,),
    seeds=1,
    attacker_steps=800,
    defender_steps=800,
    rounds=1,
    round_steps=400,
    random_episodes=50,
    starts=6,
    refine=2,
    detectors=("OBDD", "CSD", OPTIMAL),
    attacker_criteria=("mse",),
    learn_against=(OPTIMAL,),
    minimax_grid=0,
)


# --- envs and the game -------------------------------------------------------------------------
def _kwargs(scenario: str, power: float, criterion: str, statistic: str, on_detect: str) -> dict:
    return dict(
        scenario=scenario,
        power=power,
        criterion=criterion,
        statistic=statistic,
        on_detect=on_detect,
    )


def view(agent: str, opponent_action: np.ndarray, **kwargs: Any) -> gym.Env:
    """The ``agent``'s Gymnasium view with the other player fixed to ``opponent_action``."""
    return make_single_agent(MODULE, agent=agent, opponent=FixedAction(opponent_action), **kwargs)


def problem_of(scenario: str, power: float) -> DetectionProblem:
    """The design problem of the analytic detectors (docs/math.md §3)."""
    if scenario == "ch3-tracking":
        return tracking_problem(scenario, power=power)
    return static_problem(scenario, power=power)


def fixed_defender(
    name: str, scenario: str, power: float, criterion: str, optimal_tau: float
) -> tuple[DetectionGame, float]:
    """The game (env statistic and on_detect of the detector) and the detector's threshold."""
    if name == OPTIMAL:
        stat, on_detect, tau = "quadratic", "discard", optimal_tau
    else:
        det = DETECTORS[name](problem_of(scenario, power))
        stat, on_detect, tau = det.statistic, det.on_detect, det.threshold
    env = view("attacker", np.zeros(1), **_kwargs(scenario, power, criterion, stat, on_detect))
    return DetectionGame.of(env), tau


def env_reward(attack: np.ndarray, defend: np.ndarray, **kwargs: Any) -> float:
    """The attacker's reward of one env step (the cross-check of the exact reward)."""
    env = view("attacker", defend, **kwargs)
    env.reset(seed=0)
    _, reward, *_ = env.step(np.asarray(attack, dtype=np.float32))
    env.close()
    return float(reward)


def always_discards(game: DetectionGame, tau: float) -> bool:
    """The test declares every measurement an attack and discards it: every attack pays tr Pxx."""
    return game.on_detect == "discard" and tau <= 0.0  # the statistic is > 0 almost surely


# --- learning ----------------------------------------------------------------------------------
def train_sac(
    env: gym.Env,
    steps: int,
    seed: int,
    scale: float,
    score: Callable[[np.ndarray], float],
    checkpoints: int = 8,
) -> tuple[Any, list[dict[str, float]]]:
    """SAC on ``env`` (rewards divided by ``scale``); the learning curve of ``score(action)``."""
    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(1)
    scaled = gym.wrappers.TransformReward(env, lambda r: r / scale)
    kwargs = dict(SAC_KWARGS, learning_starts=min(SAC_KWARGS["learning_starts"], steps // 4))
    kwargs["learning_rate"] = _linear(SAC_KWARGS["learning_rate"])
    model = SAC("MlpPolicy", scaled, seed=seed, device="cpu", verbose=0, **kwargs)
    curve, done = [], 0
    obs, _ = env.reset(seed=seed)
    for k in range(1, checkpoints + 1):
        chunk = steps * k // checkpoints - done
        model.learn(chunk, reset_num_timesteps=False)
        done += chunk
        curve.append({"timesteps": done, "reward": score(action_of(model, obs))})
    return model, curve


def _linear(start: float) -> Callable[[float], float]:
    return lambda progress_remaining: start * progress_remaining


def action_of(model: Any, obs: np.ndarray) -> np.ndarray:
    """The deterministic action at the initial observation (the one-step game's policy)."""
    return np.asarray(model.predict(obs, deterministic=True)[0], dtype=np.float32)


# --- 1. analytic references -----------------------------------------------------------------
def defender_reference(
    scenario: str, power: float, criterion: str, seed: int = 0
) -> dict[str, Any]:
    """The best threshold against the preset attack, OBDD's α, and the env's cross-check."""
    kw = _kwargs(scenario, power, criterion, "quadratic", "discard")
    game = DetectionGame.of(view("defender", np.zeros(4), **kw))
    preset = game.attack_action(game.preset_probability, game.preset_sigma)
    best = best_threshold(game, game.preset_probability, game.preset_sigma)
    obdd = DETECTORS["OBDD"](problem_of(scenario, power))
    obdd_value = -game.attacker_reward(game.preset_probability, game.preset_sigma, obdd.threshold)
    env = view("defender", preset, **kw)
    rand = evaluate("random", env, 200, seed, Reference(best.value, "best", cost=True))
    return {
        "scenario": scenario,
        "power": power,
        "criterion": criterion,
        "best_threshold": best.threshold,
        "best_action": float(best.action[0]),
        "best_value": best.value,
        "env_value": -env_reward(preset, best.action, **kw),
        "obdd_threshold": obdd.threshold,
        "obdd_value": obdd_value,
        "obdd_score": best.value / obdd_value,
        "random_mean": rand.mean,
        "random_ci95": rand.ci95,
        "random_score": rand.score,
        "curve": {"action": best.grid.tolist(), "value": best.grid_values.tolist()},
    }


def attacker_reference(
    name: str,
    scenario: str,
    power: float,
    criterion: str,
    optimal_tau: float,
    starts: int = 16,
    refine: int = 4,
) -> dict[str, Any]:
    """The numerical best response (p, Σ) to one fixed detector, against the preset attack."""
    game, tau = fixed_defender(name, scenario, power, criterion, optimal_tau)
    kw = _kwargs(scenario, power, criterion, game.statistic, game.on_detect)
    defend = game.threshold_action(tau)
    tau_played = game.threshold(defend)
    br = best_attack(game, tau_played, starts=starts, refine=refine)
    preset = game.attacker_reward(game.preset_probability, game.preset_sigma, tau_played)
    return {
        "scenario": scenario,
        "power": power,
        "criterion": criterion,
        "detector": name,
        "threshold": tau,
        "constant": always_discards(game, tau_played),
        "preset_value": preset,
        "br_probability": br.probability,
        "br_sigma": br.sigma.tolist(),
        "br_action": br.action.tolist(),
        "br_value": br.value,
        "env_value": env_reward(br.action, defend, **kw),
        "br_gain": br.value / preset,
    }


# --- 2. and 3. learned against analytic -----------------------------------------------------
def _learned_runs(
    side: str,
    opponent: np.ndarray,
    kw: dict[str, Any],
    steps: int,
    budget: Budget,
    seed: int,
    scale: float,
    score: Callable[[np.ndarray], float],
    reference: Reference,
) -> tuple[list[float], list[float], list[np.ndarray], list[Any]]:
    """SAC on ``side``'s view against the fixed ``opponent`` action, one run per seed.

    Returns:
        Per run (seeds ``seed``, ``seed + 1``, ...): its evaluated reward, its score against
        ``reference``, its action on the first observation of ``seed`` and its learning curve.
    """
    values, scores, actions, curves = [], [], [], []
    for s in range(budget.seeds):
        env = view(side, opponent, **kw)
        model, curve = train_sac(env, steps, seed + s, scale, score)
        result = evaluate(model, env, 1, seed=seed, reference=reference)
        values.append(result.mean)
        scores.append(result.score)
        actions.append(action_of(model, env.reset(seed=seed)[0]))
        curves.append(curve)
    return values, scores, actions, curves


def learned_attacker(ref: dict[str, Any], budget: Budget, seed: int) -> dict[str, Any]:
    """SAC attackers (``budget.seeds``) against one fixed detector, scored against its BR."""
    game, _ = fixed_defender(
        ref["detector"], ref["scenario"], ref["power"], "mse", ref["threshold"]
    )
    kw = _kwargs(ref["scenario"], ref["power"], "mse", game.statistic, game.on_detect)
    defend = game.threshold_action(ref["threshold"])
    reference = Reference(ref["br_value"], "numerical best response")
    start = time.perf_counter()
    values, scores, actions, curves = _learned_runs(
        "attacker", defend, kw, budget.attacker_steps, budget, seed, abs(ref["preset_value"]),
        lambda a: game.reward(a, defend), reference,
    )  # fmt: skip
    probs = [game.attack(a)[0] for a in actions]
    rand = evaluate(
        "random", view("attacker", defend, **kw), budget.random_episodes, seed, reference
    )
    return {
        **{k: ref[k] for k in ("scenario", "power", "detector", "br_value", "preset_value")},
        "learned": mean_ci95(values),
        "learned_score": mean_ci95(scores),
        "learned_p": mean_ci95(probs),
        "random_mean": rand.mean,
        "random_score": rand.score,
        "steps": budget.attacker_steps,
        "curves": curves,
        "seconds": time.perf_counter() - start,
    }


def learned_defender(ref: dict[str, Any], budget: Budget, seed: int) -> dict[str, Any]:
    """SAC defenders (MSE criterion) against the preset attack, scored against τ* and OBDD."""
    kw = _kwargs(ref["scenario"], ref["power"], "mse", "quadratic", "discard")
    game = DetectionGame.of(view("defender", np.zeros(4), **kw))
    preset = game.attack_action(game.preset_probability, game.preset_sigma)
    reference = Reference(ref["best_value"], OPTIMAL, cost=True)
    start = time.perf_counter()
    values, scores, played, curves = _learned_runs(
        "defender", preset, kw, budget.defender_steps, budget, seed, abs(ref["best_value"]),
        lambda a: -game.reward(preset, a), reference,
    )  # fmt: skip
    actions = [float(a[0]) for a in played]
    return {
        **{k: ref[k] for k in ("scenario", "power", "best_value", "obdd_value", "obdd_score")},
        "random_score": ref["random_score"],
        "learned": mean_ci95(values),
        "learned_score": mean_ci95(scores),
        "actions": actions,
        "steps": budget.defender_steps,
        "curves": curves,
        "seconds": time.perf_counter() - start,
    }


# --- 4. learned against learned -------------------------------------------------------------
def alternating(defenders: Sequence[float], budget: Budget, seed: int) -> list[dict[str, Any]]:
    """Alternating SAC best responses from each seed's learned defender (round 0).

    Round k trains an attacker against defender k − 1, then a defender against that attacker.
    Every learned policy is scored exactly: against its opponent, against its opponent's best
    response, and (defenders) by its worst case over every attack.
    """
    scenario, power = GAME_SETTING
    kw = _kwargs(scenario, power, "mse", "quadratic", "discard")
    game = DetectionGame.of(view("defender", np.zeros(4), **kw))
    preset = game.attack_action(game.preset_probability, game.preset_sigma)
    obdd = game.threshold_action(DETECTORS["OBDD"](problem_of(scenario, power)).threshold)
    records = []
    for s, d0 in enumerate(defenders[: budget.seeds]):
        defend = np.array([d0], dtype=np.float32)
        worst = -best_attack(
            game, game.threshold(defend), starts=budget.starts, refine=budget.refine
        ).value
        records.append(
            {"seed": s, "round": 0, "side": "defender", "action": d0, "worst_case": worst}
        )
        for k in range(1, budget.rounds + 1):
            br = best_attack(game, game.threshold(defend), budget.starts, budget.refine)
            scale = max(abs(game.reward(preset, defend)), 1e-9)
            model, _ = train_sac(
                view("attacker", defend, **kw),
                budget.round_steps,
                seed + 100 * k + s,
                scale,
                lambda a, d=defend: game.reward(a, d),
                checkpoints=1,
            )
            attack = action_of(model, view("attacker", defend, **kw).reset(seed=0)[0])
            payoff = game.reward(attack, defend)
            records.append(
                {
                    "seed": s,
                    "round": k,
                    "side": "attacker",
                    "payoff": payoff,
                    "best_response": br.value,
                    "score": payoff / br.value,
                    "preset_payoff": game.reward(preset, defend),
                    "vs_obdd": game.reward(attack, obdd),
                }
            )
            p, sigma = game.attack(attack)
            best = best_threshold(game, p, sigma)
            model, _ = train_sac(
                view("defender", attack, **kw),
                budget.round_steps,
                seed + 100 * k + 50 + s,
                max(abs(best.value), 1e-9),
                lambda a, at=attack: -game.reward(at, a),
                checkpoints=1,
            )
            defend = action_of(model, view("defender", attack, **kw).reset(seed=0)[0])
            payoff = -game.reward(attack, defend)
            records.append(
                {
                    "seed": s,
                    "round": k,
                    "side": "defender",
                    "action": float(defend[0]),
                    "payoff": payoff,
                    "best_response": best.value,
                    "score": best.value / payoff,
                    "obdd_payoff": -game.reward(attack, obdd),
                    "worst_case": -best_attack(
                        game, game.threshold(defend), starts=budget.starts, refine=budget.refine
                    ).value,
                }
            )
    return records


# --- the table --------------------------------------------------------------------------------
def run_budget(budget: Budget, seed: int = 0) -> dict[str, Any]:
    """Every table's rows for ``budget`` (see the module docstring)."""
    start = time.perf_counter()
    res: dict[str, Any] = {"defender_refs": [], "attacker_refs": [], "learned_attackers": []}
    optimal: dict[tuple[str, float], float] = {}
    for scenario, power in budget.settings:
        for criterion in CRITERIA:
            ref = defender_reference(scenario, power, criterion, seed)
            res["defender_refs"].append(ref)
            if criterion == "mse":
                optimal[scenario, power] = ref["best_threshold"]
    for scenario, power in budget.settings:
        for criterion in budget.attacker_criteria:
            for name in budget.detectors:
                res["attacker_refs"].append(
                    attacker_reference(
                        name,
                        scenario,
                        power,
                        criterion,
                        optimal[scenario, power],
                        budget.starts,
                        budget.refine,
                    )
                )
    for ref in res["attacker_refs"]:
        if budget.learn_against is None:
            learn = not ref["constant"]
        else:
            learn = ref["detector"] in budget.learn_against
        if ref["criterion"] == "mse" and learn:
            res["learned_attackers"].append(learned_attacker(ref, budget, seed))
    res["learned_defenders"] = [
        learned_defender(ref, budget, seed)
        for ref in res["defender_refs"]
        if ref["criterion"] == "mse"
    ]
    res["rounds"] = []
    game_row = next(
        (r for r in res["learned_defenders"] if (r["scenario"], r["power"]) == GAME_SETTING), None
    )
    if budget.rounds and game_row is not None:
        res["rounds"] = alternating(game_row["actions"], budget, seed)
        kw = _kwargs(*GAME_SETTING, "mse", "quadratic", "discard")
        game = DetectionGame.of(view("defender", np.zeros(4), **kw))
        obdd = DETECTORS["OBDD"](problem_of(*GAME_SETTING)).threshold
        worst = best_attack(game, game.threshold(game.threshold_action(obdd)), budget.starts)
        res["obdd_worst_case"] = -worst.value
        if budget.minimax_grid:
            mm = minimax_threshold(game, grid=budget.minimax_grid)
            res["minimax"] = {
                "threshold": mm.threshold,
                "value": mm.value,
                "grid": mm.grid.tolist(),
                "worst": mm.grid_values.tolist(),
            }
    res["seconds"] = time.perf_counter() - start
    return res


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``detection_learned`` tables (Markdown); ``quick``: :data:`QUICK`."""
    res = run_budget(QUICK if quick else Budget(), seed=seed)
    if out is not None:
        rows = [
            dict(r, table=t)
            for t in (
                "defender_refs",
                "attacker_refs",
                "learned_attackers",
                "learned_defenders",
                "rounds",
            )
            for r in res[t]
        ]
        write_rows(out / "detection_learned.json", rows)
        plot(res, out)
    return format_tables(res) + f"\n\n(table time {res['seconds']:.0f} s)"
