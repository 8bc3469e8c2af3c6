"""The structure of the suite: one table of environments, and what is derived from it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import agents.registry
from fdia_env import fdia_v0
from fdia_env.registration import ENV_NAMES, ENVS, GYM_IDS, EnvEntry, register_env, torch_ids

ROOT = Path(__file__).resolve().parents[1]

TOY_MODULE = '''
"""``toy_v0``: a covariance attacker against a perfectly detecting filter, two steps."""

from fdia_env import fdia_v0

NAME = "toy_v0"


def parallel_env(**kwargs):
    return fdia_v0.parallel_env(
        scenario="ch2-position", attack="covariance", defense="perfect_detection",
        attack_kwargs={"power": 3000.0}, horizon=2, **kwargs,
    )
'''
TOY_PACKAGE = """
from fdia_env import EnvEntry, register_env

register_env(EnvEntry("toy_v0", "toy_fdia.toy_v0", {"attacker": "toy_fdia/Toy-v0"}))
"""
TOY_SCRIPT = """
import sys

import gymnasium as gym
import numpy as np
import torch

import toy_fdia  # registers the toy env: its module and one table entry, nothing else
from fdia_env.registration import ENV_NAMES, GYM_IDS, torch_ids

assert ENV_NAMES[-1] == "toy_v0" and GYM_IDS["toy_fdia/Toy-v0"] == ("toy_fdia.toy_v0", "attacker")
assert "toy_fdia/Toy-v0" in torch_ids()

action = np.array([0.3, -0.2, 0.5], dtype=np.float32)
single = gym.make("toy_fdia/Toy-v0")
single.reset(seed=3)
rewards = [single.step(action)[1] for _ in range(2)]

for backend in ("numpy", "torch"):
    vec = gym.make_vec("toy_fdia/Toy-v0", num_envs=3, vectorization_mode="vector_entry_point",
                       backend=backend)
    vec.reset(seed=3)
    for expected in rewards:
        batch = np.tile(action, (3, 1))
        batch = torch.as_tensor(batch) if backend == "torch" else batch
        got = np.asarray(vec.step(batch)[1])
        assert np.allclose(got, expected, rtol=1e-10, atol=0), (backend, got, expected)

from fdia_env import EnvEntry, register_env

register_env(EnvEntry("toy_numpy_v0", "toy_fdia.toy_numpy_v0", {"attacker": "toy_fdia/ToyNumpy-v0"},
                      backends=("numpy",)))
assert "toy_fdia/ToyNumpy-v0" not in torch_ids()
gym.make_vec("toy_fdia/ToyNumpy-v0", num_envs=2, vectorization_mode="vector_entry_point")
try:
    gym.make_vec("toy_fdia/ToyNumpy-v0", num_envs=2, vectorization_mode="vector_entry_point",
                 backend="torch")
    raise AssertionError("torch accepted for a numpy-only entry")
except ValueError as exc:
    assert "backend='torch' is not one of toy_numpy_v0's backends ['numpy']" in str(exc), exc

from agents.registry import BOX_ALGORITHMS, Trainable, covariance_reference, register

entry = register(Trainable("toy_v0", "attacker", {"ch2-position": {}}, BOX_ALGORITHMS,
                           covariance_reference))
assert entry.gym_id == "toy_fdia/Toy-v0"

from agents.rllib.envs import make_multi_agent, register_envs

names = register_envs()
assert "toy_v0" in names and "toy_fdia/Toy-v0" in names
multi = make_multi_agent("toy_v0")
obs, _ = multi.reset(seed=3)
assert list(obs) == ["attacker"]

sys.path.insert(0, "docs/_ext")
import generate_pages

assert generate_pages.ENV_MODULES[-2:] == ["toy_v0", "toy_numpy_v0"]
print("rewards", *(repr(float(r)) for r in rewards))
"""


def test_a_toy_env_registered_through_the_public_path_reaches_every_consumer(tmp_path):
    package = tmp_path / "toy_fdia"
    package.mkdir()
    (package / "__init__.py").write_text(TOY_PACKAGE, encoding="utf-8")
    (package / "toy_v0.py").write_text(TOY_MODULE, encoding="utf-8")
    (package / "toy_numpy_v0.py").write_text("from toy_fdia.toy_v0 import *\n", encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    env["OPENBLAS_NUM_THREADS"] = "1"
    result = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(TOY_SCRIPT)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    words = result.stdout.split()
    rewards = [float(w) for w in words[words.index("rewards") + 1 :]]
    # the toy env is fdia_v0 with fixed settings: same rewards as fdia_v0 built directly
    direct = fdia_v0.parallel_env(
        scenario="ch2-position",
        attack="covariance",
        defense="perfect_detection",
        attack_kwargs={"power": 3000.0},
        horizon=2,
    )
    direct.reset(seed=3)
    action = np.array([0.3, -0.2, 0.5], dtype=np.float32)
    expected = [direct.step({"attacker": action})[1]["attacker"] for _ in range(2)]
    assert rewards == expected  # bit for bit
    assert rewards[0] == 0.0 and rewards[1] > 0  # terminal reward: paid at the last step


def test_every_consumer_lists_the_table():
    views = {env_id for e in ENVS.values() for env_id in e.views.values()}
    assert set(GYM_IDS) == views
    assert torch_ids() == tuple(GYM_IDS)  # every env of the suite runs on torch
    for name, agent in agents.registry.REGISTRY:
        assert name in ENV_NAMES
        assert GYM_IDS[agents.registry.get(name, agent).gym_id] == (ENVS[name].module, agent)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "toy-v0", "module": "toy"}, "name must be a Python identifier"),
        ({"name": "toy_v0", "module": "toy/v0"}, "module must be a dotted import path"),
        ({"name": "toy_v0", "module": "toy", "views": {"referee": "toy/Toy-v0"}}, "agent must"),
        ({"name": "toy_v0", "module": "toy", "views": {"attacker": "Toy"}}, "namespace/Name-vN"),
        ({"name": "toy_v0", "module": "toy", "backends": ("jax",)}, "backends must be"),
        ({"name": "toy_v0", "module": "toy", "backends": ("torch",)}, "needs the numpy one"),
    ],
)
def test_an_entry_with_bad_fields_is_refused_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EnvEntry(**kwargs)


def test_a_name_or_gym_id_already_taken_is_refused():
    with pytest.raises(ValueError, match="already registered"):
        register_env(EnvEntry("sparse_attack_v0", "elsewhere.sparse"))
    with pytest.raises(ValueError, match="already registered"):
        register_env(EnvEntry("other_v0", "elsewhere", {"attacker": "fdia_env/SparseAttack-v0"}))
    with pytest.raises(ValueError, match=r"module 'fdia_env\.fdia_v0' is already registered"):
        register_env(EnvEntry("fdia_v1", "fdia_env.fdia_v0"))
    with pytest.raises(TypeError, match="EnvEntry"):
        register_env(("sparse_attack_v0", "fdia_env.sparse_attack_v0"))
    assert "other_v0" not in ENV_NAMES and "fdia_v1" not in ENV_NAMES
    register_env(ENVS["sparse_attack_v0"])  # the same entry again: nothing changes
    assert list(ENV_NAMES)[:2] == ["sparse_attack_v0", "covariance_attack_v0"]


def test_every_consumer_of_detector_statistics_reads_one_table():
    from baselines.detection import STATISTICS as BASELINE_NAMES
    from baselines.detection import Detector, static_problem
    from fdia_env import scenarios
    from fdia_env.defenses.detector import ThresholdDetector
    from fdia_env.detection.statistics import STATISTICS

    names = list(STATISTICS)
    assert list(BASELINE_NAMES) == names
    with pytest.raises(ValueError, match=rf"statistic must be one of \{names}".replace("'", ".")):
        ThresholdDetector(np.eye(2), statistic="likelihood")
    problem = static_problem(scenarios.get("ch3-static"), power=240.0)
    for name, entry in STATISTICS.items():
        detector = Detector("d", problem, name, 1.0, "discard")
        expected = entry.matrix(problem.Pzz0_inv, problem.Pzz1_inv)
        np.testing.assert_array_equal(detector.matrix, expected)
    # chi2's threshold scale is its mean under H0: E[y' Pzz0⁻¹ y] = tr(Pzz0⁻¹ Pzz0) = nz
    mean_h0 = np.trace(STATISTICS["chi2"].matrix(problem.Pzz0_inv, None) @ problem.Pzz0)
    assert mean_h0 == pytest.approx(STATISTICS["chi2"].scale(problem.nz), rel=1e-12)
    assert problem.nz == 2
