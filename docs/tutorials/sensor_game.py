"""Solve the sensor-selection game (LP, double oracle) and check a mix's exploitability.

Run: ``python docs/tutorials/sensor_game.py``. Learning the equilibrium with PSRO is one command:
``python train.py game --method psro --iterations 6`` (about 40 s on a 2-core machine).
"""

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
