"""RLlib PPO against the analytic optima: the sparse attacker vs EXS, PSRO and self-play.

Run: ``python benchmarks/rllib_quality.py [--seeds 0 1 2] [--sparse-steps 50000]
[--psro-iterations 6] [--selfplay-iterations 10] [--num-cpus 2]`` (needs the fdia-env[rllib]
extra). Each line is one ``train.py`` command on the rllib backend, scored by agents.evaluate
exactly as the SB3 runs are:

- ``train.py attacker --backend rllib`` on ``sparse_attack_v0`` / ch4-position (N = 6, c = 5):
  the deterministic policy's return as a fraction of EXS (0.0327856); target ≥ 99 %;
- ``train.py game --backend rllib --method psro`` on ``sensor_game_v0`` / ch5-game (value
  8.106): NashConv of the meta-mixes on the exact payoff matrix; target ≤ 1 % of the value;
- ``train.py game --backend rllib --method selfplay``: both players learning at once, NashConv
  of their average mixes (and of the last iterate).

Run folders go to a temporary directory.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.append(str(Path(__file__).resolve().parent.parent))  # after PYTHONPATH: it wins

from experiments.reproduce import machine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--sparse-steps", type=int, default=50_000)
    parser.add_argument("--psro-iterations", type=int, default=6)
    parser.add_argument("--selfplay-iterations", type=int, default=10)
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument("--skip", nargs="*", default=[], choices=["sparse", "psro", "selfplay"])
    args = parser.parse_args()

    import ray

    import train

    print(machine())
    ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    root = Path(tempfile.mkdtemp(prefix="rllib-quality-"))
    common = ["--no-progress-bar", "--runs-root", str(root)]
    if "sparse" not in args.skip:
        for seed in args.seeds:
            t0 = time.perf_counter()
            r = train.main(
                ["attacker", "--backend", "rllib", "--env", "sparse_attack_v0",
                 "--scenario", "ch4-position", "--total-timesteps", str(args.sparse_steps),
                 "--final-eval-episodes", "1", "--seed", str(seed), *common]
            )  # fmt: skip
            ev = r.evaluations["learned (RLlib PPO)"]
            print(
                f"RESULT sparse seed {seed}: {ev.mean:.7f} = {ev.score:.2%} of EXS "
                f"{ev.reference:.7f} after {r.timesteps} steps, {time.perf_counter() - t0:.0f} s",
                flush=True,
            )
    for method, iterations in (
        ("psro", args.psro_iterations),
        ("selfplay", args.selfplay_iterations),
    ):
        if method in args.skip:
            continue
        for seed in args.seeds:
            t0 = time.perf_counter()
            g = train.main(
                ["game", "--backend", "rllib", "--method", method, "--iterations",
                 str(iterations), "--final-eval-episodes", "200", "--seed", str(seed), *common]
            )  # fmt: skip
            last = g.history[-1]
            extra = (
                f" (last iterate {last['last_relative_nash_conv']:.2%})"
                if "last_relative_nash_conv" in last
                else ""
            )
            print(
                f"RESULT {method} seed {seed}: NashConv {last['nash_conv']:.4g} = "
                f"{last['relative_nash_conv']:.2%} of the value {g.value:.6g}{extra} after "
                f"{last['timesteps']} steps, {time.perf_counter() - t0:.0f} s",
                flush=True,
            )
    ray.shutdown()


if __name__ == "__main__":
    main()
