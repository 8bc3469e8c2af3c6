"""The README example of the power-grid scenarios (run from the repository root)."""

import gymnasium as gym

import fdia_env  # noqa: F401  (registers the Gymnasium ids)
from baselines.game import solve_double_oracle
from baselines.sparse import dp, exhaustive, sfs_ss
from fdia_env import scenarios
from fdia_env.systems import grid_system

# Your own grid system: IEEE 118-bus, one RTU (injection + flows at its end) per bus
rtu = grid_system("ieee118", sensors="bus")
print(f"ieee118 by RTU: n = {rtu.n} angles, M = {rtu.M} sensors, nz = {rtu.nz} measurements")

# The grid-ieee14 preset: 34 meters, c = 6 sensor-time pairs over N = 6 steps
sc = scenarios.get("grid-ieee14")
best, table = sfs_ss(sc), dp(sc)
print(f"SFS-SS tr P[K+N|K+N] = {best.value:.5e}  (DP {table.value:.5e})")
print("  attacked (step, meter):", [(k, sc.system.sensors[i].name) for k, i in best.attacks])
try:
    exhaustive(sc)
except ValueError as err:
    print("  EXS:", err)

# The same plan replayed in the Gymnasium view (MultiBinary(34) action above 16 sensors)
env = gym.make("fdia_env/SparseAttack-v0", scenario="grid-ieee14")
policy = best.policy()
obs, _ = env.reset(seed=0)
total, done = 0.0, False
while not done:
    obs, reward, done, _, _ = env.step(policy.predict(obs)[0])
    total += reward
print(f"{env.action_space} episode return = {total:.5e}")

# The sensor game with k = 2: 595 attacker and 596 defender strategies (of 2^34 - 1 each)
eq = solve_double_oracle("grid-ieee14")
names = [sc.system.sensors[i].name for (i,) in sorted(eq.attacker)]
print(f"game value {eq.value:.5e}, certified gap {eq.gap:.1e}, {eq.iterations} iterations")
print("  attacker mixes over", names)
