"""Train with Ray RLlib: a masked PPO attacker scored against EXS, PSRO on the sensor game.

The sensor game's PSRO learns each best response with RLlib PPO.

Run: ``python docs/tutorials/rllib.py`` (needs the ``fdia-env[rllib]`` extra, ray >= 2.60;
``FDIA_TUTORIAL_QUICK=1`` for a short run).
"""

import os
import tempfile

import gymnasium as gym
import ray

import fdia_env  # noqa: F401 - registers the Gymnasium ids
import train
from agents.config import Hyperparameters
from agents.evaluate import evaluate
from agents.rllib.config import agent_returns, ppo_config, steps_sampled
from agents.rllib.policy import policy_of
from baselines.sparse import exhaustive

QUICK = bool(os.environ.get("FDIA_TUTORIAL_QUICK"))
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)

# 1. The PPO config of the Gymnasium view: the attacker's observation becomes RLlib's
#    {"observations", "action_mask"}, read by RLlib's action-masking RL module (an illegal
#    action has probability 0). ppo_config registers every env under its module name or id.
kwargs = {"scenario": "ch4-position", "budget": 5, "horizon": 6}
steps = 2_000 if QUICK else 50_000
hp = Hyperparameters(n_steps=500, batch_size=100, n_epochs=4) if QUICK else None
config = ppo_config("fdia_env/SparseAttack-v0", kwargs, hp=hp, total_timesteps=steps, seed=0)
algo = config.build_algo()
done = 0
while done < steps:
    result = algo.train()
    done += steps_sampled(result)
print(f"{done} steps, last iteration's mean return {agent_returns(result)['attacker']:.6f}")

# 2. Score it: the RL module as a policy with stable-baselines3's predict, so agents.evaluate
#    plays it in the Gymnasium view beside the analytic optimum (EXS) and random play
env = gym.make("fdia_env/SparseAttack-v0", **kwargs)
learned = policy_of(algo, None, env.action_space, masked=True)
optimum = exhaustive("ch4-position", budget=5, horizon=6)
for name, policy in [("RLlib PPO", learned), ("EXS", optimum.policy()), ("random", "random")]:
    result = evaluate(policy, env, n_episodes=1 if name != "random" else 50, seed=0)
    print(f"{name:9s} {result.mean:.6f}  score {result.score:.1%} of {result.reference_name}")
algo.stop()

# 3. PSRO on the sensor game (ch5-game) with a fresh RLlib PPO best response per side and
#    iteration, the LP meta-solver, and the exact exploitability after every iteration. This is
#    `python train.py game --backend rllib --method psro`; its run folder goes to a temp dir.
#    (`train.py attacker --backend rllib` runs steps 1-2 the same way, with a run folder.)
with tempfile.TemporaryDirectory() as runs:
    game = train.main(
        ["game", "--backend", "rllib", "--method", "psro",
         "--iterations", "3" if QUICK else "6",
         "--steps-per-iteration", "1000" if QUICK else "3000",
         "--final-eval-episodes", "50" if QUICK else "1000",
         "--no-progress-bar", "--runs-root", runs]
    )  # fmt: skip
last = game.history[-1]
print(f"game value {game.value:.5f}; after {len(game.history)} iterations NashConv ", end="")
print(f"{last['nash_conv']:.3g} ({last['relative_nash_conv']:.2%} of the value)")
print("defender mix", game.x.round(3).tolist(), "attacker mix", game.y.round(3).tolist())
ray.shutdown()
