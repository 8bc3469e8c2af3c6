"""The structure of the suite: one table of environments, and what is derived from it."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import agents.registry
from fdia_env import fdia_v0
from fdia_env.registration import (
    ENV_NAMES,
    ENVS,
    GYM_IDS,
    EnvEntry,
    kalman_env_names,
    register_env,
    torch_ids,
    vector_ids,
)

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
    on_torch = [
        i
        for e in ENVS.values()
        if "torch" in e.backends
        for agent, i in e.views.items()
        if e.has_vector(agent)
    ]
    assert list(torch_ids()) == on_torch
    assert {"fdia_env/SparseAttack-v0", "fdia_env/DetectionDefender-v0"} <= set(on_torch)
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


def test_the_kalman_flag_is_a_bool_and_splits_the_table():
    with pytest.raises(TypeError, match="kalman must be a bool"):
        EnvEntry("toy_v0", "toy", kalman="no")
    assert kalman_env_names() == [n for n, e in ENVS.items() if e.kalman]
    assert "stealth_attack_v0" in ENV_NAMES and "stealth_attack_v0" not in kalman_env_names()
    stealth_id = "fdia_env/StealthAttack-v0"
    assert stealth_id in GYM_IDS and stealth_id in vector_ids() and stealth_id in torch_ids()
    assert "fdia_env/StealthDefender-v0" not in vector_ids("torch")  # copies in SyncVectorEnv
    assert ENVS["stealth_attack_v0"].vector == "fdia_env.stealth.vector:make_vector"
    with pytest.raises(ValueError, match="vector must read 'module:function'"):
        EnvEntry("toy_v0", "toy", vector="toy.make")


def test_the_table_says_which_views_have_a_native_vector_env():
    views = {"attacker": "toy/Toy-v0", "defender": "toy/ToyDefender-v0"}
    with pytest.raises(ValueError, match="vector_views must be None or a tuple of agents"):
        EnvEntry("toy_v0", "toy", {"attacker": "toy/Toy-v0"}, vector_views=("defender",))
    with pytest.raises(ValueError, match="view_kwargs must map agents with a view"):
        EnvEntry("toy_v0", "toy", {"attacker": "toy/Toy-v0"}, view_kwargs={"defender": {}})
    with pytest.raises(ValueError, match=r"\['agent'\] are set by the table"):
        EnvEntry("toy_v0", "toy", views, view_kwargs={"defender": {"agent": "attacker"}})
    entry = EnvEntry("toy_v0", "toy", views, vector_views=("attacker",))
    assert entry.has_vector("attacker") and not entry.has_vector("defender")
    assert EnvEntry("toy_v0", "toy", views).has_vector("defender")  # default: every view
    assert not EnvEntry("toy_v0", "toy", views, backends=()).has_vector("attacker")
    same = EnvEntry("toy_v0", "toy", views, view_kwargs={"defender": {"x": 1}})
    assert same == EnvEntry("toy_v0", "toy", views, view_kwargs={"defender": {"x": 1}})
    assert len({same, EnvEntry("toy_v0", "toy", views, view_kwargs={"defender": {"x": 1}})}) == 1
    # every id without a native vector env is still registered, with no vector entry point
    for entry in ENVS.values():
        for agent, env_id in entry.views.items():
            has = gym.spec(env_id).vector_entry_point is not None
            assert has == entry.has_vector(agent) == (env_id in vector_ids()), env_id


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
    copy = EnvEntry(
        "sparse_attack_v0", "fdia_env.sparse_attack_v0", {"attacker": "fdia_env/SparseAttack-v0"}
    )
    assert copy == ENVS["sparse_attack_v0"] and len({copy, ENVS["sparse_attack_v0"]}) == 1
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


# --- layering ------------------------------------------------------------------------------
# The library's layers, lowest first: a module may import from its own layer and the layers
# below it, never from one above (docs/guide/layout.md draws the same map). Longest prefix wins.
LAYERS: tuple[tuple[str, ...], ...] = (
    (
        "fdia_env._validation",
        "fdia_env.actions",
        "fdia_env.backend",
        "fdia_env.episode",
        "fdia_env.registration",
    ),
    ("fdia_env.systems", "fdia_env.kalman"),
    ("fdia_env.scenarios",),
    ("fdia_env.attacks", "fdia_env.defenses", "fdia_env.detection"),
    ("fdia_env.envs", "fdia_env.vector", "fdia_env.stealth"),
    tuple(entry.module for entry in ENVS.values()),  # the env modules, from the table
    ("fdia_env.wrappers", "fdia_env.torchrl", "fdia_env.tasks"),
    ("fdia_env",),
    ("baselines",),
    ("agents",),
    ("experiments", "benchmarks", "train"),
)
PACKAGES = ("fdia_env", "baselines", "agents", "experiments", "benchmarks")


def _modules() -> dict[str, Path]:
    mods = {"train": ROOT / "train.py"}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            mods[".".join(parts)] = path
    return mods


def _is_type_checking(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    name = getattr(test, "id", None) or getattr(test, "attr", None)
    return isinstance(node, ast.If) and name == "TYPE_CHECKING"


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement run at some point (in functions too; not ``if TYPE_CHECKING``)."""
    out, stack = [], [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.append(node)
        for child in ast.iter_child_nodes(node):
            if not _is_type_checking(child):
                stack.append(child)
    return out


def import_graph() -> dict[str, set[str]]:
    """Module → the project modules it imports (a package import is its ``__init__``)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for module, path in mods.items():
        targets = set()
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets |= {resolve(alias.name) for alias in node.names}
                continue
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                targets.add(sub if sub in mods else resolve(base))
        graph[module] = targets - {None, module}
    return graph


def layer_of(module: str) -> int:
    best = max(
        ((len(prefix), i) for i, names in enumerate(LAYERS) for prefix in names
         if module == prefix or module.startswith(prefix + ".")),
        default=None,
    )  # fmt: skip
    assert best is not None, f"{module} is in no layer: add it to LAYERS"
    return best[1]


def mutual_pairs(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Every pair of modules that import each other (directly), each pair once."""
    return sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if a in graph.get(b, ())})


def test_no_two_modules_import_each_other():
    assert mutual_pairs(import_graph()) == []


def test_no_module_imports_from_a_higher_layer():
    graph = import_graph()
    upward = sorted(
        f"{a} (layer {layer_of(a)}) imports {b} (layer {layer_of(b)})"
        for a in graph
        for b in graph[a]
        if layer_of(b) > layer_of(a)
    )
    assert upward == []


def test_the_import_graph_sees_a_mutual_import_and_an_upward_one():
    """Negative control: the scan finds what it is meant to find."""
    graph = import_graph()
    assert "fdia_env.kalman" in graph["baselines.sparse.bound"]  # a plain downward import
    assert "fdia_env.registration" in graph["fdia_env"]
    assert "baselines.sparse.bound" in graph["baselines.sparse.split"]
    # ``from package import module`` is that module, not the package's __init__
    assert "baselines.sparse.lowrank" in graph["baselines.sparse.greedy"]
    assert "baselines.sparse" not in graph["baselines.sparse.greedy"]
    assert "fdia_env.backend.torch_backend" in graph["fdia_env.backend"]  # inside a function
    assert layer_of("baselines.sparse.split") > layer_of("fdia_env")
    assert layer_of("fdia_env.kalman.linalg") < layer_of("fdia_env.envs.parallel")
    tree = ast.parse("if TYPE_CHECKING:\n    import a\ndef f():\n    import b\n")
    assert [n.names[0].name for n in _imports(tree)] == ["b"]
    # a mutual import is found whether either side imports at the top or inside a function
    toy = {"p.a": {"p.b", "p.c"}, "p.b": {"p.a"}, "p.c": set(), "p.d": {"p.c"}}
    assert mutual_pairs(toy) == [("p.a", "p.b")]
    assert mutual_pairs({**toy, "p.c": {"p.d"}}) == [("p.a", "p.b"), ("p.c", "p.d")]


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_the_system_family_env_runs_sparse_attack_v0_on_each_drawn_system(objective):
    """Its inner env, composed from the models, equals sparse_attack_v0's on the same system."""
    from fdia_env import sparse_attack_v0
    from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

    family = TrackingFamily(num_sensors=4, budget=3, horizon=3)
    env = SystemFamilyEnv(family, objective=objective)
    env.reset(seed=0, options={"system_seed": 7})
    inner = env._inner.parallel
    direct = sparse_attack_v0.parallel_env(
        scenario=env.system, budget=3, horizon=3, objective=objective
    )
    obs_a, _ = inner.reset(seed=1)
    obs_b, _ = direct.reset(seed=1)
    np.testing.assert_array_equal(
        obs_a["attacker"]["observation"], obs_b["attacker"]["observation"]
    )
    for action in (5, 0, 3):
        a = inner.step({"attacker": action})
        b = direct.step({"attacker": action})
        np.testing.assert_array_equal(
            a[0]["attacker"]["observation"], b[0]["attacker"]["observation"]
        )
        assert a[1] == b[1]
    assert a[1]["attacker"] != 0.0  # the terminal reward: Φ of the attacked window
    # the sparse part of the observation space is the inner env's, bound for bound
    box, size = env._inner.observation_space, env.sparse_size
    np.testing.assert_array_equal(env.observation_space.low[:size], box.low)
    np.testing.assert_array_equal(env.observation_space.high[:size], box.high)


def test_no_library_module_is_a_re_export_shim():
    """Every module of the installed packages defines something (a package's __init__ aside)."""
    shims = []
    for module, path in _modules().items():
        if path.name == "__init__.py" or not module.startswith(("fdia_env", "baselines", "agents")):
            continue
        body = [n for n in ast.parse(path.read_text(encoding="utf-8")).body]
        if all(isinstance(n, (ast.Import, ast.ImportFrom, ast.Expr)) for n in body):
            shims.append(module)
    assert shims == []


def test_the_layout_page_draws_the_layers_and_names_files_that_exist():
    page = (ROOT / "docs" / "guide" / "layout.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\d+) \| (.+) \|$", page, flags=re.MULTILINE)
    drawn = []
    for _, cells in rows:
        names = re.findall(r"`([\w.*]+)`", cells)
        names = [n.removesuffix(".py") for n in names]
        if names == ["fdia_env.*_vN"]:  # every version of every env module
            names = [m for m in LAYERS[len(drawn)] if re.search(r"_v\d+$", m)]
        drawn.append(tuple(names))
    assert [int(i) for i, _ in rows] == list(range(len(LAYERS)))
    assert drawn == [tuple(layer) for layer in LAYERS]
    paths = set(re.findall(r"`((?:fdia_env|baselines|agents|tests)/[\w/]+\.py)`", page))
    paths = {p for p in paths if "/my_" not in p}  # the page's example of a new env
    assert len(paths) >= 10
    assert [p for p in sorted(paths) if not (ROOT / p).is_file()] == []
