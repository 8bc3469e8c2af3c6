"""Solve the sensor-selection game (LP, double oracle), check a mix's exploitability, learn it.

Run: ``python docs/tutorials/sensor_game.py``. Section 6 learns the equilibrium with PSRO
(``python train.py game --method psro``: about 40 s for 6 iterations on a 2-core machine;
``FDIA_TUTORIAL_QUICK=1`` runs 2 short iterations, which only show that the loop runs).
"""

import os
import tempfile

import numpy as np

from baselines.game import exploitability, payoff_matrix, solve_double_oracle, solve_zero_sum
from fdia_env import sensor_game_v0, tracking_system

# 1. The payoff matrix of ch5-game (rows: the defender's subset, columns: the attacker's)
L = payoff_matrix("ch5-game", allocation="independent")
print(np.round(L, 1))

# 2. The equilibrium by linear programming (HiGHS) and its exploitability
x, y, value = solve_zero_sum(L)
nash_conv = exploitability(L, x, y).nash_conv
print(f"value {value:.4f}, defender {np.round(x, 3)}, NashConv {nash_conv:.1e}")

# 3. A uniform defender is exploitable
uniform = np.full(7, 1 / 7)
print(f"uniform defender: exploitability {exploitability(L, uniform, y).defender:.3f}")

# 4. The same payoff through the environment: defender z2z3 (index 5) against attacker z2 (1)
env = sensor_game_v0.parallel_env(scenario="ch5-game")
env.reset(seed=0)
_, rewards, *_ = env.step({"attacker": 1, "defender": 5})
print(f"L[z2z3, z2] = {rewards['attacker']:.3f} (matrix: {L[5, 1]:.3f})")

# 5. Games too large for the full matrix: double oracle with a certified gap
big = tracking_system(sigma_v=0.5, sigma_w=[1 + 0.25 * i for i in range(10)])
do = solve_double_oracle(big, power=100.0, allocation="dependent")
print(f"M = 10 (1023 strategies each): value {do.value:.6f}, gap {do.gap:.1e}")

# 6. Learn it: PSRO with a fresh PPO best response per side and iteration, the LP meta-solver
#    over the populations, and the exact exploitability of the meta-mixes after every iteration
import train  # noqa: E402 - the repository's CLI, importable from its root

QUICK = os.environ.get("FDIA_TUTORIAL_QUICK") == "1"
with tempfile.TemporaryDirectory() as runs:
    game = train.main(
        ["game", "--method", "psro", "--iterations", "2" if QUICK else "6",
         "--steps-per-iteration", "500" if QUICK else "3000",
         "--final-eval-episodes", "20" if QUICK else "1000",
         "--no-progress-bar", "--runs-root", runs]
    )  # fmt: skip
last = game.history[-1]
print(f"PSRO: {len(game.history)} iterations, NashConv {last['nash_conv']:.3g} ", end="")
print(f"({last['relative_nash_conv']:.2%} of the value {game.value:.4f})")
print("defender mix", np.round(game.x, 3).tolist())
