"""Compute the reference values of a benchmark task with the project's solvers.

:func:`compute` returns a task's :class:`~fdia_env.tasks.task.References`: random play (played in
the task's env with :func:`agents.evaluate.evaluate`, or exact for games), the polynomial
heuristics, the certified optimum (EXS, branch and bound, closed forms, LP equilibria) and the
game value, with the solver versions and the date. ``python -m agents.bench compute`` writes
them to ``fdia_env/tasks/references.json``; ``verify`` recomputes and compares
(:mod:`agents.bench.verify`).

Heuristics and optima are scored by playing their policy in the task's env where the solver
gives one (expected dynamics: the return is exact), so a stored number is a return the env pays.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import math
from typing import Any

import numpy as np

from fdia_env.tasks.catalog import TaskSpec
from fdia_env.tasks.task import GAP_HARD, Optimum, RandomReference, References, make_pinned

RANDOM_EPISODES = 200
RANDOM_SEED = 0
BNB_TIME_LIMIT = 120.0
EXS_MAX_SETS = 20_000_000
PACKAGES = ("fdia_env", "numpy", "scipy", "highspy")


def solver_versions() -> dict[str, str]:
    """Package → installed version of the packages the references depend on."""
    out = {}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return out


def _stamp() -> dict[str, Any]:
    return {"solvers": solver_versions(), "date": datetime.date.today().isoformat()}


def _random(spec: TaskSpec, episodes: int = RANDOM_EPISODES) -> RandomReference:
    from agents.evaluate import evaluate

    env = make(spec)
    try:
        try:  # the native vector env plays the same seeded episodes, batched
            result = evaluate(
                "random", env, episodes, RANDOM_SEED, reference=1.0, num_envs=episodes
            )
        except (TypeError, ValueError):  # no native vector env for this view or options
            result = evaluate("random", env, episodes, RANDOM_SEED, reference=1.0)
    finally:
        env.close()
    return RandomReference(float(result.mean), float(result.ci95), episodes, RANDOM_SEED)


def _play(spec: TaskSpec, policy: Any, episodes: int = 1) -> float:
    """The mean return of ``policy`` played in the task's env."""
    from agents.evaluate import evaluate

    env = make(spec)
    try:
        return float(evaluate(policy, env, n_episodes=episodes, seed=0, reference=1.0).mean)
    finally:
        env.close()


def make(spec: TaskSpec, **overrides: Any) -> Any:
    """The task's env (as :meth:`fdia_env.tasks.task.Task.make_env` builds it)."""
    return make_pinned(spec.env_id, spec.entry_point, {**spec.env_kwargs, **overrides})


def _ratio(objective: str, value: float, to: float) -> float:
    if objective == "logdet":
        return math.exp(value - to)
    if objective == "cost":
        return to / value
    return value / to


# ----------------------------------------------------------------------------------------------


def sparse(spec: TaskSpec, time_limit: float = BNB_TIME_LIMIT) -> References:
    """EXS (or branch and bound) for the optimum; SFS and SFS with swaps as heuristics."""
    from baselines.sparse import branch_and_bound, exhaustive, sfs, sfs_ss
    from fdia_env import scenarios

    kw = spec.env_kwargs
    objective = kw.get("objective", "trace")
    scenario = kw["scenario"]
    args = (scenario, kw["budget"], kw["horizon"], objective)
    action = kw.get("action", "auto")
    M = scenarios.resolve(scenario).system.M
    if math.comb(M * kw["horizon"], kw["budget"]) <= EXS_MAX_SETS:
        best = exhaustive(*args)
        name, bound = "EXS", best.value
        certified = True
    else:
        best = branch_and_bound(*args, time_limit=time_limit)
        certified = bool(best.proved_optimal)
        name = "B&B (certified optimum)" if certified else "B&B incumbent (certified bound)"
        bound = best.value if certified else float(best.upper_bound)
    fmt = "sequential" if action == "sequential" else None
    value = _play(spec, best.policy(fmt) if fmt else best.policy())
    heuristics = {}
    for label, solver in (("SFS", sfs), ("SFS-SS", sfs_ss)):
        result = solver(*args)
        heuristics[label] = _play(spec, result.policy(fmt) if fmt else result.policy())
    gap = 0.0 if certified else 1.0 - _ratio(objective, value, bound)
    return References(
        objective=objective,
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, name, certified, bound, gap),
        game_value=None,
        **_stamp(),
    )


def covariance(spec: TaskSpec) -> References:
    """The closed-form optimum, with heuristics.

    The heuristics are the independent-bias optimum and, for log det, the trace-optimal attack.
    """
    from baselines.covariance import det_optimal, trace_optimal

    kw = spec.env_kwargs
    objective = kw.get("objective", "trace")
    env = make(spec)
    try:
        if objective == "trace":
            best, name = trace_optimal(kw["scenario"], kw["power"]), "trace-optimal"
        else:
            best, name = det_optimal(kw["scenario"], kw["power"]), "det-optimal (water-filling)"
        policies = {"independent biases": trace_optimal(kw["scenario"], kw["power"], "diagonal")}
        if objective == "logdet":
            policies["trace-optimal"] = trace_optimal(kw["scenario"], kw["power"])
        value = _play(spec, best.policy(env.unwrapped.parallel))
        heuristics = {k: _play(spec, r.policy(env.unwrapped.parallel)) for k, r in policies.items()}
    finally:
        env.close()
    return References(
        objective=objective,
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, name, True, value, 0.0),
        game_value=None,
        **_stamp(),
    )


def _game_objective(player: str) -> str:
    """The attacker's payoff is a value (ratio raw / v), the defender's a cost (ratio v / raw)."""
    return "value" if player == "attacker" else "cost"


def _worst_case_matrix(L: np.ndarray, player: str, mix: np.ndarray) -> float:
    """The player's return against a best response.

    The attacker's is ``min_D (L y)_D``, the defender's ``−max_A (x'L)_A``.
    """
    return float((L @ mix).min()) if player == "attacker" else -float((mix @ L).max())


def sensor_game(spec: TaskSpec) -> References:
    """The LP game value; uniform play and the best pure strategy, each at its worst case."""
    from baselines.game import payoff_matrix, solve_zero_sum

    kw = spec.env_kwargs
    env = make(spec)
    try:
        parallel = env.unwrapped.parallel
        attack = parallel.attack
        L = payoff_matrix(
            parallel.scenario, attack.power, attack.allocation, attack.max_subset_size
        )
        check_stored_payoff(spec.name, L, parallel.scenario, attack)
    finally:
        env.close()
    _, _, value = solve_zero_sum(L)
    player = spec.player
    n = L.shape[1] if player == "attacker" else L.shape[0]
    own = value if player == "attacker" else -value
    uniform = _worst_case_matrix(L, player, np.full(n, 1.0 / n))
    pure = max(_worst_case_matrix(L, player, row) for row in np.eye(n))
    del kw
    return References(
        objective=_game_objective(player),
        metric="worst-case return",
        random=RandomReference(uniform, 0.0, 0, RANDOM_SEED),
        heuristics={"best pure strategy": pure},
        optimum=Optimum(own, "game value (LP)", True, own, 0.0),
        game_value=own,
        **_stamp(),
    )


def check_stored_payoff(name: str, L: np.ndarray, scenario: Any, attack: Any) -> None:
    """Raise when a stored payoff of this game (``fdia_env.tasks.payoffs``) differs from ``L``.

    Raises:
        RuntimeError: When the stored matrix's shape differs or an entry differs by more than
            1e-9 relative to the largest entry.
    """
    from fdia_env.tasks.payoffs import stored_payoff

    stored = stored_payoff(scenario, attack.power, attack.allocation, attack.max_subset_size)
    if stored is None:
        return
    scale = float(np.abs(L).max()) or 1.0
    if stored.shape != L.shape or float(np.abs(stored - L).max()) > 1e-9 * scale:
        raise RuntimeError(
            f"{name}: the stored payoff matrix differs from the one rebuilt now; rewrite it with "
            f"python -m agents.bench payoff --task {name}"
        )


def write_stored_payoff(spec: TaskSpec) -> Any:
    """Build the payoff matrix of a sensor-game task and store it; the file's path."""
    from baselines.game import payoff_matrix
    from fdia_env.tasks.payoffs import write_payoff

    if spec.family != "sensor-game":
        raise ValueError(f"task must be a sensor-game task, got {spec.name!r} ({spec.family})")
    env = make(spec)
    try:
        parallel = env.unwrapped.parallel
        a = parallel.attack
        L = payoff_matrix(parallel.scenario, a.power, a.allocation, a.max_subset_size)
        return write_payoff(L, parallel.scenario, a.power, a.allocation, a.max_subset_size)
    finally:
        env.close()


def incomplete_information(spec: TaskSpec) -> References:
    """The Bayesian game's LP value; uniform play and the best pure strategy at worst case."""
    from baselines.game import bayesian_game_of

    env = make(spec)
    try:
        game = bayesian_game_of(env.unwrapped.parallel)
    finally:
        env.close()
    m, n = game.matrices.shape[1:]
    value = game.value
    if spec.player == "attacker":
        own = value
        uniform = game.attacker_worst_case(np.full(n, 1.0 / n))
        pure = max(game.attacker_worst_case(e) for e in np.eye(n))
    else:
        own = -value
        uniform = -game.defender_worst_case(np.full(m, 1.0 / m))
        pure = max(-game.defender_worst_case(e) for e in np.eye(m))
    return References(
        objective=_game_objective(spec.player),
        metric="worst-case return",
        random=RandomReference(float(uniform), 0.0, 0, RANDOM_SEED),
        heuristics={"best pure strategy": float(pure)},
        optimum=Optimum(float(own), "Bayesian equilibrium (LP)", True, float(own), 0.0),
        game_value=float(own),
        **_stamp(),
    )


def detection_game(spec: TaskSpec) -> References:
    """The defender's or the attacker's references (:func:`detection_defender`, ``_attacker``)."""
    if spec.player == "attacker":
        return detection_attacker(spec)
    return detection_defender(spec)


def detection_attacker(spec: TaskSpec) -> References:
    """The best response to the view's fixed detector, with a certified upper bound.

    The attacker's expected Bayes cost ``p R1(Σ) + (1 − p) R0`` is linear in p, so the best
    response attacks with p = 1 (or never); Σ is searched by
    :func:`baselines.detection.response.best_attack` (seeded multi-start, Nelder-Mead). That is
    the best known value, not a proof, so the bound is certified apart: with the detector
    discarding what it flags, ``R1(Σ) = P_d c1 + P_miss c2(Σ) ≤ max(c1, c2(Σ))``, c1 (the
    prior's error) does not depend on Σ, and c2 is linear in Σ, largest at the c2-maximising
    Σ of the power (closed form, docs/math.md §3); so every attack earns at most
    ``max(R0, c1, max c2)``. Heuristics: the preset attacker (p1, the c2-maximising Σ) and the
    always-on attack with that Σ, played in the env.
    """
    import dataclasses

    from baselines.detection.detectors import strategy_costs
    from baselines.detection.response import DetectionGame, best_attack
    from fdia_env.detection_game_v0 import FixedAction

    env = make(spec)
    try:
        game = DetectionGame.of(env)
        tau = game.threshold(env.unwrapped.opponent.predict(None)[0])
    finally:
        env.close()
    if game.on_detect != "discard" or game.criterion != "bayes_cost":
        raise ValueError(f"{spec.name}: the bound needs on_detect='discard' and the Bayes cost")
    best = best_attack(game, tau)
    value = _play(spec, FixedAction(best.action))
    if not math.isclose(value, best.value, rel_tol=1e-6):
        raise RuntimeError(f"{spec.name}: the best attack played in the env gives {value}")
    truth = dataclasses.replace(game.design, Pbb=game.preset_sigma, p1=1.0)
    costs = strategy_costs(game.design, game.on_detect, truth)  # Σ = the c2-maximising one
    bound = max(best.no_attack, costs.c1, costs.c2)
    heuristics = {
        "preset attack (p1, c2-maximising covariance)": _play(
            spec, FixedAction(game.attack_action(game.preset_probability, game.preset_sigma))
        ),
        "always attack (c2-maximising covariance)": _play(
            spec, FixedAction(game.attack_action(1.0, game.preset_sigma))
        ),
    }
    return _best_known(spec, heuristics, value, "best response (multi-start search)", bound)


def detection_defender(spec: TaskSpec) -> References:
    """OBDD's threshold (the Bayes-cost optimum), with the χ² test at 5 % false alarms.

    The optimum is played in the env as a fixed threshold; the χ² test's Bayes cost is computed.
    """
    from agents.registry import parallel_of
    from baselines.detection import bayes_cost, csd, obdd, static_problem, tracking_problem
    from fdia_env.detection_game_v0 import FixedAction, _is_static

    kw = spec.env_kwargs
    env = make(spec)
    try:
        parallel = parallel_of(env)
        det = parallel.defense
        static = _is_static(parallel.system)
        problem = (static_problem if static else tracking_problem)(
            kw["scenario"], power=kw["power"]
        )
        best = obdd(problem)
        chi2 = csd(problem)
        action_of = det.threshold_to_action
    finally:
        env.close()
    value = _play(spec, FixedAction(action_of(best.threshold)))
    if not math.isclose(value, -bayes_cost(best).value, rel_tol=1e-6):
        raise RuntimeError(f"{spec.name}: OBDD played in the env gives {value}, not its Bayes cost")
    heuristics = {"chi2 test (5 % false alarms)": -bayes_cost(chi2).value}
    return References(
        objective="cost",
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, f"{best.name} threshold (Bayes cost)", True, value, 0.0),
        game_value=None,
        **_stamp(),
    )


def _play_seeded(env: Any, policy: Any, options: dict[str, Any]) -> float:
    """One episode of ``policy`` in ``env`` reset with ``options``: its return."""
    obs, _ = env.reset(seed=0, options=options)
    total, done = 0.0, False
    while not done:
        action, _ = policy.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += float(reward)
        done = terminated or truncated
    return total


def system_family(spec: TaskSpec) -> References:
    """The family's expected optimum, with SFS as the heuristic.

    EXS on every system of ``system_seeds`` (each drawn with equal probability), played in the
    env with the system pinned; SFS likewise.
    """
    from baselines.sparse import exhaustive, sfs

    env = make(spec)
    try:
        view = env.unwrapped
        family, seeds, objective = view.family, view.system_seeds, view.objective
        best, greedy = [], []
        for k in seeds:
            scenario = family.scenario(k)
            args = (scenario, family.budget, family.horizon, objective)
            options = {"system_seed": k}
            best.append(_play_seeded(env, exhaustive(*args).policy(), options))
            greedy.append(_play_seeded(env, sfs(*args).policy(), options))
    finally:
        env.close()
    value = float(np.mean(best))
    return References(
        objective="trace" if objective == "trace" else "logdet",
        metric="return",
        random=_random(spec),
        heuristics={"SFS": float(np.mean(greedy))},
        optimum=Optimum(value, f"EXS on each of the {len(seeds)} systems", True, value, 0.0),
        game_value=None,
        **_stamp(),
    )


def stealth(spec: TaskSpec) -> References:
    """The static env's references (below), or the dynamic env's (:func:`stealth_dynamic`)."""
    if spec.env_id == "fdia_env/StealthDynamic-v0":
        return stealth_dynamic(spec)
    if spec.env_id == "fdia_env/StealthDynamicDefender-v0":
        return stealth_protect(spec)
    return stealth_static(spec)


def greedy_shift(returns: np.ndarray, n: int) -> int:
    """Local search over shift patterns: the pattern it stops at (an index into ``returns``).

    It starts from the best single-state shift and flips one state in or out at a time, always
    the flip that raises the return most, until no flip raises it (at most ``n`` returns looked
    up per flip: polynomial, given the returns of the patterns it visits).

    Args:
        returns: ``(2^n,)`` the return of every pattern, pattern ``i`` shifting the states of
            the set bits of ``i``.
        n: Number of states.
    """
    current = max((1 << j for j in range(n)), key=lambda i: returns[i])
    while True:
        flips = [current ^ (1 << j) for j in range(n) if current ^ (1 << j)]
        best = max(flips, key=lambda i: returns[i])
        if returns[best] <= returns[current]:
            return current
        current = best


def stealth_static(spec: TaskSpec) -> References:
    """The optimum over every shift pattern, with the best single-state shift as heuristic.

    All patterns of the ``action="shift"`` (or ``"box_shift"``) space are played at once in the
    native vector env (expected dynamics: exact returns). With ``"box_shift"`` the local search
    of :func:`greedy_shift` from the best single-state shift is a heuristic too.
    """
    import gymnasium

    env = make(spec)
    try:
        n = int(env.action_space.n)
    finally:
        env.close()
    if n > 16:
        raise ValueError(f"{spec.name}: 2^{n} shift patterns are too many to enumerate")
    bits = ((np.arange(2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    venv = gymnasium.make_vec(
        spec.env_id, num_envs=2**n, vectorization_mode="vector_entry_point", **spec.env_kwargs
    )
    try:
        venv.reset(seed=0)
        _, rewards, *_ = venv.step(bits)
    finally:
        venv.close()
    horizon = int(spec.env_kwargs.get("horizon", 1))
    returns = np.asarray(rewards, dtype=np.float64) * horizon  # the same snapshot every step
    value = float(returns.max())
    heuristics = {"best single-state shift": float(returns[[1 << j for j in range(n)]].max())}
    if spec.env_kwargs.get("action") == "box_shift":
        heuristics["local search from the best single-state shift"] = float(
            returns[greedy_shift(returns, n)]
        )
    return References(
        objective="trace",
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, f"exhaustive over the 2^{n} shift patterns", True, value, 0.0),
        game_value=None,
        **_stamp(),
    )


def stealth_dynamic(spec: TaskSpec) -> References:
    """Bias attacks on ``stealth_dynamic_v0``: the best constant-sign bias, a certified bound.

    The best known value is the best of the 2^r constant attacks ``a_max · s`` (s a sign
    pattern over the r attacked rows), played in the env. The bound: a bias only raises the
    non-central χ² statistic, so each step is detected with probability ``p ≥ α`` and pays at
    most ``(1 − α) · phi``; ``phi_k = tr P_f + |d_k|²`` with ``d_k = −Σ_j Ā^{k−j} K Γ a_j``, so
    ``|d_k| ≤ Σ_{i<k} max_s |Ā^i K Γ s|`` (a convex function of a is largest at a vertex of
    the action box). The heuristic is Mo & Sinopoli's stealthy attack
    (:func:`baselines.stealth.dynamic.mo_sinopoli`) scaled to the largest bias, or nothing
    when the attacked sensors admit none.
    """
    import itertools

    from baselines.stealth.dynamic import mo_sinopoli
    from fdia_env.stealth.dynamic_policy import ScheduledPolicy, bias_actions
    from fdia_env.stealth.stealth_attack_v0 import _Fixed

    kw = spec.env_kwargs
    if kw.get("action") != "bias" or kw.get("dynamics") != "expected":
        raise ValueError(f"{spec.name}: the bound needs action='bias' and expected dynamics")
    if kw.get("on_detect", "zero") != "zero" or kw.get("protected"):
        raise ValueError(f"{spec.name}: the bound needs on_detect='zero' and no protected sensor")
    env = make(spec)
    try:
        parallel = env.unwrapped.parallel
        model, horizon, alpha = parallel.model, int(parallel.horizon), float(parallel.alpha)
    finally:
        env.close()
    r = len(model.rows)
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=r)))
    returns = [_play(spec, _Fixed(s.astype(np.float32))) for s in signs]
    value = float(max(returns))
    gamma = np.zeros((model.m, r))
    gamma[model.rows, np.arange(r)] = model.a_max * model.sigma
    reach, power = [], np.eye(model.n)
    for _ in range(horizon):
        reach.append(float(np.linalg.norm(power @ model.K @ gamma @ signs.T, axis=0).max()))
        power = model.Abar @ power
    bound = (1.0 - alpha) * sum(model.clean + sum(reach[:k]) ** 2 for k in range(1, horizon + 1))
    heuristics = {}
    system = model.system
    ms = mo_sinopoli(system.F, system.H, system.Q, system.R, model.rows.tolist())
    if ms.reach is not None:
        injections = ms.attack(horizon)
        peak = float(np.abs(injections[:, model.rows] / (model.a_max * model.sigma)).max())
        if peak > 0.0:
            actions = bias_actions(model, injections * ((1.0 - 1e-12) / peak))
            heuristics["Mo-Sinopoli stealthy attack (scaled to a_max)"] = _play(
                spec, ScheduledPolicy(actions)
            )
    return _best_known(spec, heuristics, value, f"best of the 2^{r} constant-sign biases", bound)


PROTECT_MAX_SEQUENCES = 100_000


def protection_schedule(sequence: Any, sensors: int) -> Any:
    """The defender's policy protecting sensor ``sequence[k] − 1`` at step k (0: none)."""
    from fdia_env.stealth.dynamic_policy import ScheduledPolicy

    table = np.zeros((len(sequence), sensors))
    for k, choice in enumerate(sequence):
        if choice:
            table[k, choice - 1] = 1.0
    return ScheduledPolicy(table)


def protection_returns(spec: TaskSpec, sequences: list[tuple[int, ...]]) -> np.ndarray:
    """The defender's return of each open-loop protection sequence (0 none, j sensor j − 1).

    The env is deterministic (expected dynamics, a fixed attacker), so a sequence's return is
    one episode's; a prefix shorter than the horizon returns its steps' sum.
    """
    env = make(spec)
    try:
        choices = np.eye(int(env.action_space.n), dtype=np.int8)
        out = np.empty(len(sequences))
        for i, sequence in enumerate(sequences):
            env.reset(seed=0)
            total = 0.0
            for choice in sequence:
                action = choices[choice - 1] if choice else np.zeros_like(choices[0])
                total += float(env.step(action)[1])
            out[i] = total
    finally:
        env.close()
    return out


def stealth_protect(spec: TaskSpec) -> References:
    """The protecting defender of ``stealth_dynamic_v0``: the optimum by enumeration.

    Against a fixed attacker in expected dynamics the env is deterministic, so the best policy
    is the best open-loop sequence of protections (every policy plays one): each of the
    ``(M + 1)^N`` sequences (no protection or one of the M sensors at each of the N steps) is
    played and the best is the certified optimum. Heuristics: the best fixed protection (the
    same choice at every step) and the greedy defender (each step the choice that maximises
    the return so far, given its earlier choices).
    """
    import itertools

    kw = spec.env_kwargs
    if kw.get("defender") != "protect" or kw.get("protect_budget", 1) != 1:
        raise ValueError(f"{spec.name}: the enumeration needs defender='protect', budget 1")
    if kw.get("dynamics") != "expected":
        raise ValueError(f"{spec.name}: the enumeration needs expected dynamics")
    env = make(spec)
    try:
        M, horizon = int(env.action_space.n), int(env.unwrapped.parallel.horizon)
    finally:
        env.close()
    if (M + 1) ** horizon > PROTECT_MAX_SEQUENCES:
        raise ValueError(f"{spec.name}: {(M + 1) ** horizon:,} protection sequences are too many")
    sequences = list(itertools.product(range(M + 1), repeat=horizon))
    returns = protection_returns(spec, sequences)
    best = sequences[int(np.argmax(returns))]
    value = _play(spec, protection_schedule(best, M))
    if not math.isclose(value, float(returns.max()), rel_tol=1e-9):
        raise RuntimeError(f"{spec.name}: the best sequence played as a policy gives {value}")
    fixed = max(protection_returns(spec, [(c,) * horizon for c in range(M + 1)]))
    greedy: tuple[int, ...] = ()
    for _ in range(horizon):
        options = [(*greedy, c) for c in range(M + 1)]
        greedy = options[int(np.argmax(protection_returns(spec, options)))]
    heuristics = {
        "best fixed protection": float(fixed),
        "greedy protection": _play(spec, protection_schedule(greedy, M)),
    }
    name = f"exhaustive over the {M + 1}^{horizon} protection sequences"
    return References(
        objective="cost",
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, name, True, value, 0.0),
        game_value=None,
        **_stamp(),
    )


def _best_known(
    spec: TaskSpec, heuristics: dict[str, float], value: float, method: str, bound: float
) -> References:
    """References of a return-maximising task: a best known ``value`` and a certified bound.

    ``method`` names how ``value`` was found; the optimum counts as proved when the gap closes.
    """
    gap = 1.0 - _ratio("trace", value, bound)
    return References(
        objective="trace",
        metric="return",
        random=_random(spec),
        heuristics=heuristics,
        optimum=Optimum(value, method, gap <= 0.0, max(bound, value), gap),
        game_value=None,
        **_stamp(),
    )


FAMILIES = {
    "sparse": sparse,
    "covariance": covariance,
    "sensor-game": sensor_game,
    "incomplete-information": incomplete_information,
    "detection-game": detection_game,
    "system-family": system_family,
    "stealth": stealth,
}


def compute(spec: TaskSpec) -> References:
    """The references of the task ``spec`` (its family's function above).

    Raises:
        ValueError: For a family without a reference computation here.
    """
    if spec.family not in FAMILIES:
        raise ValueError(f"no reference computation for family {spec.family!r} ({spec.name})")
    refs = FAMILIES[spec.family](spec)
    if refs.optimum.gap > GAP_HARD and refs.optimum.certified:
        raise RuntimeError(f"{spec.name}: a certified optimum with a gap")
    return refs
