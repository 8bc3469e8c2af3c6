"""benchmarks/seq_throughput.py and its rows of the summary table of docs/benchmarks.md."""

import importlib.util
import sys
from pathlib import Path

import gymnasium as gym
import pytest

ROOT = Path(__file__).resolve().parent.parent


def _load(name: str, file: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / file)
    module = sys.modules.get(name) or importlib.util.module_from_spec(spec)
    if name not in sys.modules:
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return module


report = _load("bench_report", "report.py")
seq = _load("bench_seq_throughput", "seq_throughput.py")

OUTPUT = """\
setting                              way  decisions/s (CPU)     (wall)  x bitmask (CPU)
ieee14-rtu bitmask                 1 env                 93         30             1.0x
ieee14-rtu sequential (time)       1 env               1245        389            13.4x
ieee14-rtu sequential (plan)       1 env               1268        409            13.7x
grid-ieee14 sequential (time)      1 env               1352        425            14.6x
grid-ieee14 sequential (plan)      1 env               1224        389            13.2x
zero-cost env                      1 env               1651        636            17.8x
ieee14-rtu bitmask                8 envs                 97         36             1.0x
ieee14-rtu sequential (plan)      8 envs               2760        914            28.4x
grid-ieee14 sequential (plan)     8 envs               2690        849            27.6x
target: every sequential setting >= 20x the bitmask, 1 env: NOT met
target: every sequential setting >= 20x the bitmask, 8 envs: met"""


def test_summary_rows_read_each_way_and_the_zero_cost_bound():
    bench = next(b for b in report.BENCHES if b.name == "seq_throughput")
    one, eight = bench.summary(OUTPUT)
    assert "1 env" in one[0] and "8 envs" in eight[0]
    assert one[1:] == (
        "13.2× to 14.6× (an env that costs nothing: 17.8×), target NOT met",
        "bitmask 93 decisions/s (CPU)",
    )
    assert eight[1:] == ("27.6× to 28.4×, target met", "bitmask 97 decisions/s (CPU)")


def test_the_zero_cost_env_has_the_real_envs_spaces_and_does_nothing():
    kwargs = dict(scenario="ch4-position", budget=2, horizon=3, action="sequential", order="plan")
    real = gym.make(seq.GYM_ID, **kwargs)
    env = seq.ZeroCostEnv(real, 3)
    assert env.observation_space == real.observation_space
    assert env.action_space == real.action_space == gym.spaces.Discrete(3 * 3 + 1)
    obs, _ = env.reset(seed=0)
    assert [env.step(5)[2] for _ in range(3)] == [False, False, True]
    assert obs.shape == real.observation_space.shape and not obs.any()
    assert env.action_masks().all()


@pytest.mark.parametrize("argv", [["--steps", "2"], ["--repeats", "0"]])
def test_bad_options_are_refused(argv, capsys):
    with pytest.raises(SystemExit):
        seq.main(argv)
    settings = seq.train_settings()[seq.WAYS[1]]  # train.py's default on the grid presets
    rollout = settings["n_steps"] * seq.VECTOR_ENVS  # one rollout of its 8 members
    assert f"--steps must be >= {rollout} (one rollout)" in capsys.readouterr().err


def test_each_way_trains_the_env_as_described():
    from fdia_env.vector.sb3 import SB3VecEnv

    settings = seq.train_settings()
    assert seq.train_setup().num_envs == seq.VECTOR_ENVS  # train.py's default
    assert (settings["8 envs"]["n_steps"], settings["8 envs"]["batch_size"]) == (128, 256)
    assert (settings["1 env"]["n_steps"], settings["1 env"]["batch_size"]) == (512, 128)
    order = seq.train_setup().env_kwargs["order"]  # the plan-first order train.py picks
    assert order == "increasing"
    assert {k: v.get("order") for k, v in seq.formats().items() if "(time)" not in k} == {
        seq.BASELINE: None,
        "ieee14-rtu sequential (increasing)": order,
        "grid-ieee14 sequential (increasing)": order,
        seq.BOUND: order,
    }
    kwargs = dict(scenario="ch4-position", budget=2, horizon=3, action="sequential", order=order)
    one = seq.make_model(kwargs, seq.WAYS[0], settings[seq.WAYS[0]], seed=0)
    monitor = one.get_env().envs[0]  # SB3 wraps a gym env in a Monitor
    assert monitor.unwrapped.parallel.order == order
    assert (one.n_envs, one.n_steps) == (1, 512)
    eight = seq.make_model(kwargs, seq.WAYS[1], settings[seq.WAYS[1]], seed=0)
    assert isinstance(eight.get_env(), SB3VecEnv) and eight.n_envs == seq.VECTOR_ENVS
    assert (eight.n_steps, eight.batch_size) == (128, 256)  # per member, as train.py
