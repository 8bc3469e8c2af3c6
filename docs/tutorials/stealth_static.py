"""Stealthy attacks on static grid state estimation: attack, play it in the env, protect meters.

Run: ``python docs/tutorials/stealth_static.py`` (needs the ``[grid]`` extra, pandapower).
"""

import numpy as np

from baselines.stealth import (
    budgeted_attack,
    protection_exploitability,
    protection_game,
    security_index,
)
from fdia_env.stealth import static_estimation, stealth_attack_v0

# 1. The IEEE 14-bus grid's DC state estimation and its bad-data test
est = static_estimation("ieee14", alpha=0.05)
print(f"m = {est.m} meters, n = {est.n} states, chi2 threshold {est.threshold:.3f} (dof {est.dof})")

# 2. Undetectable attacks a = H c: the residual does not move, the estimate moves by c
c = np.zeros(est.n)
c[6] = 0.05
a = est.H @ c
print(f"a = H c: detection probability {est.detection_probability(a):.3f} (= alpha)")
print(
    f"estimate shift {np.round(est.estimate_shift(a), 6)[6]}, meters touched {np.count_nonzero(a)}"
)
noise = np.zeros(est.m)
noise[0] = 0.05
print(f"a single bad meter: detection probability {est.detection_probability(noise):.3f}")

# 3. Exact baselines: security indices (min cut) and the best 3-meter attack on state 6 (MILP)
index = security_index(est, method="mincut")
print("security indices:", index.indices.astype(int).tolist())
best = budgeted_attack(est, budget=3, a_max=0.5, target=6)
print(f"budgeted attack, 3 meters: state {best.target}, meters {best.meters}, {best.value:.4f} rad")

# 4. The attack played in the environment (expected dynamics: the exact expected payoff)
env = stealth_attack_v0.parallel_env(est, budget=3, action="free", a_max=0.5, dynamics="expected")
env.reset(seed=0)
action, _ = best.policy(a_max=0.5).predict(env.state())
_, rewards, *_ = env.step({"attacker": action})
print(f"env reward {rewards['attacker']:.4f} = (1 - alpha) x {best.value:.4f}")

# 5. Protecting meters: the game against a defender with a protection budget (small H)
H = np.random.default_rng(0).choice([-1.0, 0.0, 0.0, 0.0, 1.0, 2.0], size=(8, 3))
game = protection_game(H, budget=4, protection=1, a_max=1.0)
print(f"game value {game.value:.6f}, gap {game.gap:.1e}, {game.iterations} restricted games")
print("defender's mix:", {k: round(p, 4) for k, p in sorted(game.defender.items())})
for meters in [(3,), (0,)]:
    conceded, _ = protection_exploitability(H, meters, budget=4, a_max=1.0)
    print(f"always protecting meter {meters[0]} concedes {conceded:.6f}")
