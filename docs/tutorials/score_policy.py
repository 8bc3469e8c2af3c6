"""Score your own policy on a benchmark task: raw return, normalised score, references.

Run: ``python docs/tutorials/score_policy.py``.
"""

from agents.bench.score import report, score_policy
from fdia_env.tasks import get

# 1. A named task: its env, its player and its stored references
task = get("sparse/ch4-position-v0")
print(task.name, "|", task.family, task.player, task.difficulty)
print(task.description)
refs = task.references
print(
    f"random {refs.random.mean:.6f}, SFS {refs.heuristics['SFS']:.6f}, EXS {refs.optimum.value:.6f}"
)


# 2. Your policy: any object with stable-baselines3's predict (a function works too)
class LastSteps:
    """Attack every sensor (action 7 = all three bits) in the window's last two steps."""

    def predict(
        self, observation, state=None, episode_start=None, deterministic=True, action_masks=None
    ):
        """Action 7 when at most two of the six steps are left, else no attack."""
        steps_left = observation[0]  # steps left / window length
        return (7 if steps_left <= 2 / 6 + 1e-9 else 0), state


# 3. Score it: 3 evaluation seeds x the task's episodes, normalised 0 = random, 1 = optimum
result = score_policy(task, LastSteps(), seeds=(0, 1, 2), agent="LastSteps")
print(report(result, task))

# 4. Random play on the reference's own episodes (seed 0, 200 episodes) scores 0 exactly
rand = score_policy(task, "random", seeds=(0,), episodes=refs.random.episodes)
print(f"random play: raw {rand.mean:.6f}, normalised {rand.normalised:.4f}")
