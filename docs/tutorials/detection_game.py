"""The detection game: the literature's detectors, and a threshold sweep through the env.

Run: ``python docs/tutorials/detection_game.py``.
"""

import numpy as np

from baselines.detection import bayes_cost, csd, expected_mse, obdd, obdi, static_problem
from fdia_env import detection_game_v0

# 1. The analytic detectors at a² = 240 on ch3-static: Bayes cost and true mean squared error
problem = static_problem("ch3-static", power=240.0)
for detector in (obdd(problem), obdi(problem), csd(problem)):
    cost = bayes_cost(detector)
    print(
        f"{detector.name:4s} α = {detector.threshold:8.4f}  Bayes cost {cost.value:7.3f}  "
        f"true MSE {expected_mse(detector):7.3f}"
    )

# 2. The env pays the exact expected squared error of the defender's threshold
env = detection_game_v0.parallel_env(scenario="ch3-static", power=240.0, criterion="bayes_cost")
attack = detection_game_v0.default_opponent(env, "defender").predict(None)[0]
costs = {}
for tau in np.linspace(0.05, 6.0, 120):
    env.reset(seed=0)
    _, rewards, *_ = env.step(
        {"attacker": attack, "defender": env.defense.threshold_to_action(tau)}
    )
    costs[tau] = rewards["attacker"]
best = min(costs, key=costs.get)
print(f"best threshold on the grid {best:.2f} (OBDD's α {obdd(problem).threshold:.2f})")
