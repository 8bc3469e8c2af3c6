"""Stealthy attacks on a Kalman filter: Mo & Sinopoli's and Guo et al.'s attacks in the env.

Run: ``python docs/tutorials/stealth_dynamic.py``.
"""

import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401  (registers the Gymnasium ids)
from baselines.stealth import mo_sinopoli, optimal_linear_attack
from fdia_env.stealth import stealth_dynamic_v0
from fdia_env.stealth.dynamic_policy import bias_actions, linear_action
from fdia_env.systems import LinearSystem, Sensor

# 1. Which sensor sets admit an unbounded stealthy attack (ch4-position: 3 position sensors)
env = stealth_dynamic_v0.parallel_env(dynamics="expected", horizon=800, a_max=1e6)
model = env.model
s = model.system
for sensors in ([0], [0, 1], [0, 1, 2]):
    print(f"sensors {sensors}: vulnerable {mo_sinopoli(s.F, s.H, s.Q, s.R, sensors).vulnerable}")

# 2. The attack played in the env: the error grows without bound, detection stays near α
attack = mo_sinopoli(s.F, s.H, s.Q, s.R, model.rows)
actions = bias_actions(model, attack.attack(800, scale=2e-3))  # over a_max · σ per row
env.reset(seed=0)
p_max = 0.0
for k in range(800):
    _, rewards, _, _, infos = env.step({"attacker": actions[k]})
    info = infos["attacker"]
    p_max = max(p_max, info["detection_probability"])
    if k + 1 in (100, 200, 400, 800):
        print(f"step {k + 1:3d}: tr error cov {info['phi']:.4f} (clean {model.clean:.4f})")
print(f"largest detection probability {p_max:.4f} (alpha 0.05)")

# 3. The same attack sampled in 400 filters at once: the alarm rate is the exact one
B, steps = 400, 200
venv = gym.make_vec(
    "fdia_env/StealthDynamic-v0",
    num_envs=B,
    vectorization_mode="vector_entry_point",
    a_max=1e6,
    horizon=steps,
)
venv.reset(seed=1)
alarms, exact = [], []
for k in range(steps):
    _, _, _, _, info = venv.step(np.repeat(actions[k][None], B, axis=0))
    alarms.append(info["detected"].mean())
    exact.append(info["detection_probability"].mean())
print(f"alarm rate {np.mean(alarms[4:]):.3f}, exact {np.mean(exact[4:]):.4f}")
print(f"mean squared error at step {steps}: {info['error'].mean():.3f}")

# 4. Guo et al.'s optimal linear attack on a stable system, played in the env
sensors = (
    Sensor(H=np.array([[1.0, 0.0]]), R=np.array([[0.5]]), name="s1"),
    Sensor(H=np.array([[1.0, 1.0]]), R=np.array([[1.0]]), name="s2"),
)
system = LinearSystem(F=[[0.9, 0.2], [0.0, 0.7]], Q=np.diag([0.3, 0.2]), sensors=sensors)
for delta in (0.0, 0.5):
    best = optimal_linear_attack(system.F, system.H, system.Q, system.R, delta)
    env = stealth_dynamic_v0.parallel_env(
        system, action="linear", dynamics="expected", horizon=150, window=1
    )
    action = linear_action(env.model, best.T)  # T = I + t_max · action[:, :2], b = 0
    env.reset(seed=0)
    for _ in range(150):
        _, _, _, _, infos = env.step({"attacker": action})
    info = infos["attacker"]
    print(
        f"delta {delta}: closed form {best.value:.4f}, env {info['phi']:.4f} "
        f"(clean {best.clean:.4f}), KL {info['kl']:.4f}, "
        f"detection probability {info['detection_probability']:.4f}"
    )
