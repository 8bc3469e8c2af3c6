"""The protection game: a defender protects meters, an attacker picks a stealthy budgeted attack.

Zero-sum, simultaneous. The defender protects ``protection`` meters (a set P; a protected
meter's reading cannot be altered). The attacker corrupts at most ``budget`` meters with an
undetectable injection ``a = H c``, ``|a_i| ≤ a_max`` (a set A of meters and the shift c). If
the defender protected a meter of A, the injection is no longer of the form ``H c`` and the
bad-data test is there to catch it: the game counts it as worth nothing. Otherwise the attacker
gains the damage the env pays, the largest change of any state's estimate ``|K a|_∞ = |c|_∞``:

    L(P, (A, c)) = |c|_∞ · [P ∩ A = ∅]

(Kim & Poor 2011 protect meters against such attacks; as a game with a protection budget it is
the stealthy counterpart of the sensor-selection game, docs/references.md.) The strategy sets are
far too large to write down (every P of ``protection`` meters, every attack), so it is solved by
double oracle (McMahan, Gordon & Blum 2003), as :func:`baselines.game.solve_double_oracle`
solves the sensor game, with exact best responses by mixed-integer programming (scipy's HiGHS):

- attacker, against a mix x over sets P_j: for each target state t, ``max Σ_j x_j u_j`` over
  c, y ∈ {0, 1}^m (meters used), z_j ∈ {0, 1} (P_j avoided) with ``|(H c)_i| ≤ a_max y_i``,
  ``Σ y ≤ budget``, ``y_i + z_j ≤ 1`` (i ∈ P_j), ``u_j ≤ c_t``, ``u_j ≤ U_t z_j`` (U_t the
  largest shift of t on the budget with nothing protected, so the product ``c_t z_j`` is exact);
- defender, against a mix y over attacks (A_k, c_k): ``max Σ_k y_k |c_k|_∞ h_k`` over
  p ∈ {0, 1}^m, ``Σ p = protection``, ``h_k ≤ Σ_{i∈A_k} p_i``, ``0 ≤ h_k ≤ 1`` (weighted
  maximum coverage: the damage the protection stops).

Against the restricted equilibrium (x, y), ``lower = min_P L(P, y) ≤ v* ≤ max_A L(x, A) = upper``
bounds the full game's value v*, so ``gap = upper − lower`` certifies the result (it is the
NashConv of the returned pair). :func:`protection_exploitability` scores any protection (a
learned defender's, a heuristic's) the same way: the damage a best-responding attacker gets
against it, to compare with the game's value.

>>> import numpy as np
>>> H = np.random.default_rng(0).choice([-1.0, 0.0, 0.0, 0.0, 1.0, 2.0], size=(8, 3))
>>> game = protection_game(H, budget=4, protection=1, a_max=1.0)
>>> round(game.value, 6), game.gap <= 1e-6 * game.value, sorted(game.defender)
(0.166667, True, [(3,), (6,), (7,)])

On IEEE 14 (``a_max = 0.5``) one protected meter stops every 3-meter attack (value 0); with 5
meters against 2 protected the value is 0.02996 rad (15 restricted games).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize, sparse

from baselines.game.lp import solve_zero_sum
from baselines.stealth.attack import StealthyAttack, _a_max, _attack, _budget_milp, check_budget
from baselines.stealth.common import as_estimation, milp, null_space, support
from baselines.stealth.policy import MixedActionPolicy
from fdia_env._validation import check_int, check_positive

Meters = tuple[int, ...]


@dataclass(frozen=True, eq=False)
class ProtectionGame:
    """A certified equilibrium of the protection game (see the module docstring).

    Attributes:
        value: Value of the last restricted game: the damage (rad) the attacker expects.
        lower: ``min_P L(P, y)``: the attacker's mix guarantees at least this damage.
        upper: ``max_A L(x, A)``: the defender's mix concedes at most this damage.
        gap: ``upper − lower`` ≥ 0 (up to the MILPs' tolerance): the pair's NashConv.
        defender: ``{protected meters: probability}`` over the defender's support.
        attacks: The attacker's support (undetectable attacks ``a = H c``).
        attack_probs: Their probabilities.
        budget: Meters the attacker may corrupt.
        protection: Meters the defender protects.
        a_max: The bound on each injection (per unit), one per meter.
        m: Number of meters.
        iterations: Restricted games solved.
        seconds: Wall time.
    """

    value: float
    lower: float
    upper: float
    gap: float
    defender: dict[Meters, float]
    attacks: tuple[StealthyAttack, ...]
    attack_probs: tuple[float, ...]
    budget: int
    protection: int
    a_max: np.ndarray
    m: int
    iterations: int
    seconds: float

    def policy(self, player: str = "defender", seed: int | None = None) -> MixedActionPolicy:
        """The equilibrium strategy of ``player`` as a policy (SB3 ``predict`` signature).

        - ``"attacker"``: plays each attack ``a / a_max`` (``stealth_attack_v0`` with
          ``action="free"`` and this ``a_max``) with its probability;
        - ``"defender"``: plays the (m,) 0/1 vector of a protected set with its probability.
          ``stealth_attack_v0`` has no protecting defender to play it in: score a protection
          with :func:`protection_exploitability`, or fix one set with the env's ``protected``
          option.

        Raises:
            ValueError: For another ``player``.
        """
        if player == "attacker":
            table = [k.a / self.a_max for k in self.attacks]
            return MixedActionPolicy(table, self.attack_probs, seed, dtype=np.float32)
        if player == "defender":
            rows = np.zeros((len(self.defender), self.m))
            for j, meters in enumerate(self.defender):
                rows[j, list(meters)] = 1.0
            return MixedActionPolicy(rows, list(self.defender.values()), seed, dtype=np.int8)
        raise ValueError(f"player must be 'attacker' or 'defender', got {player!r}")


def _check_protection(est: Any, protection: Any) -> int:
    return check_int("protection", protection, minimum=0, maximum=est.m)


def _bounds(est: Any, budget: int, bound: np.ndarray, time_limit: float | None) -> np.ndarray:
    """(n,) U_t: the largest shift of each state on the budget with nothing protected.

    The certified upper bound of each solve (the shift itself unless it stopped at
    ``time_limit``), so that pruning by U_t and the big-M ``u_j ≤ U_t z_j`` stay valid.
    """
    none = np.zeros(0, dtype=np.int64)
    return np.array(
        [_budget_milp(est, t, budget, bound, none, time_limit)[2] for t in range(est.n)]
    )


def _clean(est: Any, c: np.ndarray, used: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """The MILP's c re-solved exactly on its meters (as the budgeted attack does)."""
    zero = np.setdiff1d(np.arange(est.m), used)
    N = null_space(est.H[zero], est.n)
    if N.shape[1] == 0:
        return np.zeros(est.n)
    c = N @ (N.T @ c)
    over = float(np.max(np.abs(est.H @ c) / bound))
    return c / over if over > 1.0 else c


def _attacker_payoff(meters: Meters, damage: float, sets: list[Meters], x: np.ndarray) -> float:
    hit = np.array([bool(set(meters) & set(p)) for p in sets])
    return float(damage * np.sum(x[~hit]))


def _attacker_response(
    est: Any,
    budget: int,
    bound: np.ndarray,
    U: np.ndarray,
    sets: list[Meters],
    x: np.ndarray,
    time_limit: float | None,
) -> tuple[float, StealthyAttack | None]:
    """The attack with the largest expected damage against the protection mix ``x``."""
    keep = [j for j in range(len(sets)) if x[j] > 0.0]
    sets_k, x_k = [sets[j] for j in keep], x[keep]
    m, n, r = est.m, est.n, len(keep)
    scale = np.max(np.abs(est.H), axis=1)
    scale[scale == 0.0] = 1.0
    Hn = est.H / scale[:, None]
    M = sparse.diags(bound / scale)
    # variables (c: n, y: m, z: r, u: r)
    zr, ur = sparse.csr_matrix((m, r)), sparse.csr_matrix((m, r))
    rows = [
        sparse.hstack([Hn, -M, zr, ur]),
        sparse.hstack([-Hn, -M, zr, ur]),
        sparse.hstack([sparse.csr_matrix((1, n)), np.ones((1, m)), np.zeros((1, 2 * r))]),
    ]
    upper = [np.zeros(2 * m), [budget]]
    pairs = [(i, j) for j, p in enumerate(sets_k) for i in p]
    if pairs:
        data = np.ones(2 * len(pairs))
        ri = np.repeat(np.arange(len(pairs)), 2)
        ci = np.array([[n + i, n + m + j] for i, j in pairs]).reshape(-1)
        rows.append(sparse.csr_matrix((data, (ri, ci)), shape=(len(pairs), n + m + 2 * r)))
        upper.append(np.ones(len(pairs)))
    best: tuple[float, StealthyAttack | None] = (0.0, None)
    for t in np.argsort(-U, kind="stable"):
        Ut = float(U[t]) * (1.0 + 1e-6) + 1e-12
        if U[t] <= best[0] or U[t] <= 0.0:
            break  # no attack on t (or a later state) can beat the best found
        link = sparse.lil_matrix((2 * r, n + m + 2 * r))
        for j in range(r):
            link[j, n + m + r + j], link[j, t] = 1.0, -1.0  # u_j ≤ c_t
            link[r + j, n + m + r + j], link[r + j, n + m + j] = 1.0, -Ut  # u_j ≤ U_t z_j
        A = sparse.vstack([*rows, link.tocsr()], format="csr")
        cost = np.zeros(n + m + 2 * r)
        cost[n + m + r :] = -x_k
        lb = np.concatenate([np.full(n, -np.inf), np.zeros(m + 2 * r)])
        ub = np.concatenate([np.full(n, np.inf), np.ones(m + r), np.full(r, np.inf)])
        res = milp(
            cost,
            constraints=optimize.LinearConstraint(
                A, -np.inf, np.concatenate([*upper, np.zeros(2 * r)])
            ),
            integrality=np.concatenate([np.zeros(n), np.ones(m + r), np.zeros(r)]),
            bounds=optimize.Bounds(lb, ub),
            options=_options(time_limit),
        )
        if res.x is None:
            raise RuntimeError(f"HiGHS found no attacker best response on state {t}: {res.message}")
        c = _clean(est, res.x[:n], np.flatnonzero(res.x[n : n + m] > 0.5), bound)
        a = est.H @ c
        meters = tuple(int(i) for i in support(a))
        damage = float(np.max(np.abs(c)))
        value = _attacker_payoff(meters, damage, sets, x)
        if value > best[0] + 1e-12:
            best = (
                value,
                _attack(a, c, target=int(t), value=damage, objective="shift", budget=budget),
            )
    return best


def _options(time_limit: float | None) -> dict[str, Any]:
    options: dict[str, Any] = {"mip_rel_gap": 1e-9}
    if time_limit is not None:
        options["time_limit"] = float(time_limit)
    return options


def _defender_response(
    m: int, protection: int, attacks: list[StealthyAttack], y: np.ndarray, time_limit: float | None
) -> Meters:
    """The protected set that stops the most expected damage of the attack mix ``y``."""
    s = len(attacks)
    w = np.array([yk * k.value for yk, k in zip(y, attacks, strict=True)])
    cover = sparse.lil_matrix((s, m + s))
    for k, attack in enumerate(attacks):
        cover[k, m + k] = 1.0
        for i in attack.meters:
            cover[k, i] = -1.0  # h_k ≤ Σ_{i ∈ A_k} p_i
    total = np.concatenate([np.ones(m), np.zeros(s)])[None, :]
    res = milp(
        np.concatenate([np.zeros(m), -w]),
        constraints=[
            optimize.LinearConstraint(cover.tocsr(), -np.inf, 0.0),
            optimize.LinearConstraint(total, protection, protection),
        ],
        integrality=np.concatenate([np.ones(m), np.zeros(s)]),
        bounds=optimize.Bounds(np.zeros(m + s), np.ones(m + s)),
        options=_options(time_limit),
    )
    if res.x is None:
        raise RuntimeError(f"HiGHS found no defender best response: {res.message}")
    chosen = np.flatnonzero(res.x[:m] > 0.5)
    return tuple(int(i) for i in chosen)


def _defender_cost(meters: Meters, attacks: list[StealthyAttack], y: np.ndarray) -> float:
    p = set(meters)
    return float(
        sum(yk * k.value for yk, k in zip(y, attacks, strict=True) if not p & set(k.meters))
    )


def protection_game(
    estimation: Any = "ieee14",
    budget: int = 3,
    protection: int = 1,
    *,
    a_max: Any = 0.5,
    tol: float = 1e-6,
    max_iter: int = 200,
    time_limit: float | None = None,
) -> ProtectionGame:
    """Equilibrium of the protection game by double oracle (module docstring).

    Args:
        estimation: A :class:`~fdia_env.stealth.StaticEstimation` or what
            :func:`~fdia_env.stealth.static_estimation` accepts (grid case or preset, an H).
        budget: Meters the attacker may corrupt, 1..m.
        protection: Meters the defender protects, 0..m.
        a_max: Largest injection per meter (per unit), one number or m of them (the env's
            ``a_max`` with ``action="free"``).
        tol: Stop when ``gap ≤ tol · upper`` (> 0).
        max_iter: Most restricted games to solve (≥ 1).
        time_limit: HiGHS seconds per MILP (``None``: none). An attacker best response that
            stops at the limit is its best attack found, so ``upper`` and ``gap`` are then not
            certified; leave it ``None`` for a certified value.

    Returns:
        A :class:`ProtectionGame`; if the gap does not close to ``tol`` within ``max_iter``, it
        carries the gap reached (certified bounds ``lower ≤ v* ≤ upper`` either way).

    Raises:
        ValueError: Naming the parameter: a budget outside 1..m, a protection outside 0..m,
            a_max ≤ 0 or non-finite, tol ≤ 0, max_iter < 1.
    """
    start = time.perf_counter()
    est = as_estimation(estimation)
    budget = check_budget(est, budget)
    protection = _check_protection(est, protection)
    bound = _a_max(est, a_max)
    tol = check_positive("tol", tol)
    max_iter = check_int("max_iter", max_iter, minimum=1)
    if time_limit is not None:
        time_limit = check_positive("time_limit", time_limit)
    U = _bounds(est, budget, bound, time_limit)
    sets: list[Meters] = [()]  # nothing protected yet: the attacker's unprotected best attack
    _, first = _attacker_response(est, budget, bound, U, sets, np.ones(1), time_limit)
    if first is None:  # no undetectable attack on the budget: the game is worth 0
        return ProtectionGame(
            value=0.0, lower=0.0, upper=0.0, gap=0.0, defender={tuple(range(protection)): 1.0},
            attacks=(),
            attack_probs=(), budget=budget, protection=protection, a_max=bound, m=est.m,
            iterations=0, seconds=time.perf_counter() - start,
        )  # fmt: skip
    attacks = [first]
    sets = [_defender_response(est.m, protection, attacks, np.ones(1), time_limit)]
    iteration = 0
    while True:
        iteration += 1
        L = np.array([[k.value * (not set(p) & set(k.meters)) for k in attacks] for p in sets])
        x, y, value = solve_zero_sum(L)
        best_set = _defender_response(est.m, protection, attacks, y, time_limit)
        lower = min(_defender_cost(best_set, attacks, y), float(np.min(L @ y)))
        upper, best_attack = _attacker_response(est, budget, bound, U, sets, x, time_limit)
        upper = max(upper, float(x @ L @ y), float(np.max(x @ L)))
        if upper - lower <= tol * max(abs(upper), 1e-300) or iteration >= max_iter:
            break
        grew = False
        if best_set not in sets:
            sets.append(best_set)
            grew = True
        if best_attack is not None and not any(
            k.meters == best_attack.meters and abs(k.value - best_attack.value) <= 1e-12
            for k in attacks
        ):
            attacks.append(best_attack)
            grew = True
        if not grew:
            break
    return ProtectionGame(
        value=float(value),
        lower=float(lower),
        upper=float(upper),
        gap=float(upper - lower),
        defender={p: float(q) for p, q in zip(sets, x, strict=True) if q > 0},
        attacks=tuple(k for k, q in zip(attacks, y, strict=True) if q > 0),
        attack_probs=tuple(float(q) for q in y if q > 0),
        budget=budget,
        protection=protection,
        a_max=bound,
        m=est.m,
        iterations=iteration,
        seconds=time.perf_counter() - start,
    )


def as_protection_mix(est: Any, protection: Any, param: str = "protection") -> dict[Meters, float]:
    """A protection mix ``{meters: probability}`` from a mix, one meter set or a 0/1 vector.

    Raises:
        ValueError: Naming ``param``, for unknown meters or probabilities that are negative or
            do not sum to 1.
    """
    if isinstance(protection, dict):
        items = list(protection.items())
    else:
        arr = np.asarray(protection)
        if (
            arr.dtype != object
            and arr.ndim == 1
            and arr.size == est.m
            and np.isin(arr, (0, 1)).all()
        ):
            items = [(tuple(int(i) for i in np.flatnonzero(arr)), 1.0)]
        else:
            items = [(protection, 1.0)]
    mix: dict[Meters, float] = {}
    for meters, p in items:
        key = tuple(int(i) for i in est.meter_positions(meters, param))
        if not (isinstance(p, (int, float, np.integer, np.floating)) and np.isfinite(p) and p >= 0):
            raise ValueError(f"{param}: probabilities must be finite numbers >= 0, got {p!r}")
        mix[key] = mix.get(key, 0.0) + float(p)
    total = sum(mix.values())
    if abs(total - 1.0) > 1e-9:
        raise ValueError(f"{param}: probabilities must sum to 1, got {total!r}")
    return mix


def protection_exploitability(
    estimation: Any,
    protection: Any,
    budget: int = 3,
    *,
    a_max: Any = 0.5,
    time_limit: float | None = None,
) -> tuple[float, StealthyAttack | None]:
    """The damage a best-responding attacker gets against a protection (and its attack).

    Scores any defender: at the game's equilibrium it equals the value; every other protection
    concedes at least that much. ``protection`` is a mix ``{meters: probability}`` (e.g. the
    empirical mix of a learned defender's actions), one set of meters (positions or names) or
    an (m,) 0/1 vector.

    Raises:
        ValueError: Naming the parameter, as :func:`protection_game` and
            :func:`as_protection_mix`.
    """
    est = as_estimation(estimation)
    budget = check_budget(est, budget)
    bound = _a_max(est, a_max)
    mix = as_protection_mix(est, protection)
    U = _bounds(est, budget, bound, time_limit)
    sets = list(mix)
    return _attacker_response(est, budget, bound, U, sets, np.array(list(mix.values())), time_limit)


def matrix_game(
    estimation: Any, budget: int, protection: int, *, a_max: Any = 0.5, max_meters: int = 12
) -> tuple[list[Meters], list[tuple[Meters, float]], np.ndarray]:
    """The whole payoff matrix of a small protection game, by enumeration (a check).

    Rows: every set of ``protection`` meters; columns: every set A of at most ``budget``
    meters with its best undetectable attack (largest ``|c|_∞`` with ``H c`` zero off A and
    ``|H c| ≤ a_max``, one LP per state), kept when it is non-zero.

    Raises:
        ValueError: Above ``max_meters`` meters (the enumeration is exponential).
    """
    est = as_estimation(estimation)
    budget = check_budget(est, budget)
    protection = _check_protection(est, protection)
    bound = _a_max(est, a_max)
    if est.m > max_meters:
        raise ValueError(
            f"estimation: the enumeration takes at most {max_meters} meters, got {est.m}"
        )
    columns: list[tuple[Meters, float]] = []
    for size in range(1, budget + 1):
        for A in itertools.combinations(range(est.m), size):
            damage = _lp_damage(est, A, bound)
            if damage > 1e-12:
                columns.append((A, damage))
    rows = list(itertools.combinations(range(est.m), protection))
    L = np.array([[v * (not set(P) & set(A)) for A, v in columns] for P in rows])
    return rows, columns, L.reshape(len(rows), len(columns))


def _lp_damage(est: Any, A: Meters, bound: np.ndarray) -> float:
    """Largest ``|c|_∞`` with ``H c`` zero off A and ``|H c| ≤ a_max`` (exact)."""
    off = np.setdiff1d(np.arange(est.m), A)
    N = null_space(est.H[off], est.n)  # c = N w
    if N.shape[1] == 0:
        return 0.0
    HA = est.H[list(A)] @ N
    if N.shape[1] == 1:  # a line of attacks: scale it to the first bound it meets
        size = np.abs(HA[:, 0])
        if not np.any(size > 1e-12):
            return 0.0
        return float(np.max(np.abs(N)) * np.min(bound[list(A)][size > 1e-12] / size[size > 1e-12]))
    best = 0.0
    for t in range(est.n):
        res = optimize.linprog(
            -N[t],
            A_ub=np.vstack([HA, -HA]),
            b_ub=np.concatenate([bound[list(A)], bound[list(A)]]),
            bounds=[(None, None)] * N.shape[1],
            method="highs",
        )
        if res.status == 0:
            best = max(best, -float(res.fun))
    return best
