"""Bring your own linear system or a pandapower grid: build it, check it, attack it, solve it.

Run: ``python docs/tutorials/own_system.py``.
"""

import numpy as np

from baselines.sparse import dp, exhaustive, sfs
from fdia_env import LinearSystem, Sensor, sparse_attack_v0

# 1. A 3-state system watched by three scalar sensors
system = LinearSystem(
    F=np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 0.9]]),
    Q=0.01 * np.eye(3),
    sensors=(
        Sensor(H=[[1.0, 0.0, 0.0]], R=[[0.2]], name="position"),
        Sensor(H=[[0.0, 1.0, 1.0]], R=[[0.5]], name="rate"),
        Sensor(H=[[1.0, 0.0, 1.0]], R=[[0.3]], name="mixed"),
    ),
    name="three-state",
)

# 2. Systems are checked when built: an undetectable one is a clear error
try:
    LinearSystem(F=1e6 * np.eye(2), Q=np.eye(2), sensors=(Sensor(H=[[1.0, 0.0]], R=[[1.0]]),))
except ValueError as err:
    print("rejected:", str(err)[:60], "...")

# 3. Every env and solver takes it in place of a preset name
for solver in (exhaustive, sfs, dp):
    result = solver(system, budget=3, horizon=4)
    print(f"{solver.__name__:10s} tr P = {result.value:.6f}  attacks {result.attacks}")

env = sparse_attack_v0.parallel_env(scenario=system, budget=3, horizon=4)
env.reset(seed=0)
policy = exhaustive(system, budget=3, horizon=4).policy()
total = 0.0
while env.agents:
    action, _ = policy.predict(env.state())
    _, rewards, *_ = env.step({"attacker": action})
    total += rewards["attacker"]
print(f"EXS plan played in the env: {total:.6f}")

# 4. A power grid from pandapower (the [grid] extra): DC state estimation of the IEEE 14-bus case
from fdia_env.systems import grid_system  # noqa: E402

grid = grid_system("ieee14", sensors="bus")  # one RTU (injection + flows) per bus
print(f"ieee14: n = {grid.n} bus angles, M = {grid.M} RTUs, nz = {grid.nz} measurements")
print(f"SFS on the grid, 3 RTU-steps over 4 steps: tr P = {sfs(grid, 3, 4).value:.4e}")
