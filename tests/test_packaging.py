"""The installed package: console scripts, metadata, env imports, what ``make demo`` installs."""

import ast
import importlib
import json
import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from packaging.requirements import Requirement

import fdia_env
from fdia_env.registration import ENV_NAMES, get_env

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
SCRIPTS = PYPROJECT["project"].get("scripts", {})
BOUNDED = "stealth/ch4-position-dynamic-bias-v0"  # its reference: best known value + bound


def _resolve(value: str):
    module, _, attr = value.partition(":")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


# --- console scripts -----------------------------------------------------------------------


def test_the_console_scripts_are_the_three_commands_and_resolve_to_callables():
    assert SCRIPTS == {
        "fdia-train": "agents.train:cli",
        "fdia-bench": "agents.bench.__main__:main",
        "fdia-leaderboard": "agents.leaderboard.cli:main",
    }
    for value in SCRIPTS.values():
        assert callable(_resolve(value)), value


def test_the_installed_distribution_declares_the_same_console_scripts():
    """The metadata of the installed fdia-env (make setup reinstalls it when pyproject changes)."""
    installed = {
        ep.name: ep for ep in metadata.distribution("fdia-env").entry_points
        if ep.group == "console_scripts"
    }  # fmt: skip
    assert sorted(installed) == ["fdia-bench", "fdia-leaderboard", "fdia-train"]
    assert {name: ep.value for name, ep in installed.items()} == SCRIPTS
    for ep in installed.values():
        assert callable(ep.load()), ep


def test_the_console_scripts_print_their_help_under_their_own_name(monkeypatch, capsys):
    from agents.leaderboard import cli as leaderboard
    from agents.train import cli as train_cli

    monkeypatch.setattr(sys, "argv", ["/venv/bin/fdia-train", "--help"])
    with pytest.raises(SystemExit) as stop:
        train_cli()
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert out.lstrip().startswith("usage: fdia-train [-h]")
    assert "fdia-train attacker --algo MaskablePPO" in out and "python train.py" not in out
    monkeypatch.setattr(sys, "argv", ["/venv/bin/fdia-leaderboard", "--help"])
    with pytest.raises(SystemExit):
        leaderboard.main()
    assert capsys.readouterr().out.startswith("usage: fdia-leaderboard [-h]")


def test_train_py_and_experiments_bench_are_the_installed_modules():
    import agents.leaderboard.render
    import agents.leaderboard.run
    import agents.train
    import experiments.bench.render
    import experiments.bench.run
    import train

    assert train is agents.train  # so a monkeypatch of train.X reaches the code that runs
    assert experiments.bench.run is agents.leaderboard.run
    assert experiments.bench.render is agents.leaderboard.render
    assert train.program() == ("train.py", "python train.py")  # pytest is not fdia-train


def test_python_train_py_and_python_m_experiments_bench_still_run(tmp_path):
    """The checkout's commands, from the root; the runner refuses to run without --out."""
    train = subprocess.run(
        [sys.executable, "train.py", "attacker", "--env", "no_such_env"],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert train.returncode == 2
    assert train.stderr.startswith("train.py: error: "), train.stderr
    assert "no_such_env" in train.stderr
    page = tmp_path / "page.md"
    bench = subprocess.run(
        [sys.executable, "-m", "experiments", "bench", "--tasks", "hard", "--page", str(page)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert bench.returncode == 2
    assert (
        "python -m experiments bench: error: the following arguments are required: --out"
        in bench.stderr
    )
    assert not page.exists()


# --- metadata: license and version -----------------------------------------------------------


def test_the_license_is_in_the_pep_639_form_with_its_file():
    project = PYPROJECT["project"]
    assert project["license"] == "MIT"
    assert project["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License\n\nCopyright (c) the fdia_env developers\n")
    assert 'THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND' in text
    # license/license-files as strings need setuptools 77 (older ones warn or refuse them)
    requires = [Requirement(r) for r in PYPROJECT["build-system"]["requires"]]
    setuptools = next(r for r in requires if r.name == "setuptools")
    assert "76.9" not in setuptools.specifier and "77.0.0" in setuptools.specifier


def test_the_version_has_one_source():
    project = PYPROJECT["project"]
    assert "version" not in project and project["dynamic"] == ["version"]
    attr = PYPROJECT["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "fdia_env.__version__"
    tree = ast.parse((ROOT / "fdia_env" / "__init__.py").read_text(encoding="utf-8"))
    literal = [
        n.value.value for n in tree.body
        if isinstance(n, ast.Assign) and [t.id for t in n.targets] == ["__version__"]
    ]  # fmt: skip
    assert literal == [fdia_env.__version__]  # a literal setuptools reads without importing
    assert re.fullmatch(r"\d+\.\d+\.\d+", fdia_env.__version__)
    assert metadata.version("fdia-env") == fdia_env.__version__


# --- from fdia_env import <env> ---------------------------------------------------------------


@pytest.mark.parametrize("name", ENV_NAMES)
def test_every_registered_env_module_imports_from_the_package(name):
    namespace: dict = {}
    exec(f"from fdia_env import {name}", namespace)
    module = namespace[name]
    assert module is importlib.import_module(get_env(name).module)
    assert callable(module.parallel_env)
    assert name in dir(fdia_env)


def test_the_stealth_envs_import_from_the_package_and_other_names_do_not():
    from fdia_env import stealth_attack_v0, stealth_dynamic_v0

    assert stealth_attack_v0.__name__ == "fdia_env.stealth.stealth_attack_v0"
    assert stealth_dynamic_v0.__name__ == "fdia_env.stealth.stealth_dynamic_v0"
    with pytest.raises(ImportError, match="no_such_env_v0"):
        exec("from fdia_env import no_such_env_v0", {})
    assert not hasattr(fdia_env, "no_such_env_v0")


# --- the score's scale on a bounded reference --------------------------------------------------


def _report(name: str) -> str:
    from agents.bench.score import Score, report
    from fdia_env.tasks import get

    task = get(name)
    score = Score(
        task=name, agent="random", description="", seeds=(0,), returns=np.array([[0.0, 0.0]]),
        mean=0.0, ci95=0.0, normalised=0.0, normalised_ci=(0.0, 0.0), per_seed=(0.0,),
    )  # fmt: skip
    return report(score, task)


def test_a_bounded_reference_says_1_is_the_best_known_value_and_scores_the_bound():
    """The legend is agents.bench.score.scale_legend (the same code as the docs branch's)."""
    stored = json.loads((ROOT / "fdia_env" / "tasks" / "references.json").read_text())[BOUNDED]
    best, random = stored["optimum"], stored["random"]["mean"]
    assert best["certified"] is False
    # the bound's normalised score, from the stored numbers: (bound − random)/(best − random)
    bound_score = (best["bound"] - random) / (best["value"] - random)
    assert bound_score == pytest.approx(1.12320, abs=1e-5)
    line = next(s for s in _report(BOUNDED).splitlines() if s.startswith("normalised"))
    assert line == (
        "normalised  0.0000 [0.0000, 0.0000] (0 = random, 1 = best known (best of the 2^3 "
        "constant-sign biases); the optimum is at most 1.1232)"
    )
    assert "1 = optimum" not in _report(BOUNDED)


def test_a_certified_reference_keeps_1_as_the_optimum():
    line = next(
        s for s in _report("sparse/ch4-position-v0").splitlines() if s.startswith("normalised")
    )
    assert line == "normalised  0.0000 [0.0000, 0.0000] (0 = random, 1 = optimum)"


# --- make demo: the core dependencies only ---------------------------------------------------


def _extras_only_modules() -> list[str]:
    """Top-level import names of the extras' packages that the core dependencies do not pull."""

    def closure(requirements: list[Requirement]) -> set[str]:
        seen, todo = set(), list(requirements)
        while todo:
            req = todo.pop()
            name = req.name.lower().replace("_", "-")
            if name in seen or (req.marker and not req.marker.evaluate({"extra": ""})):
                continue
            seen.add(name)
            try:
                todo += [Requirement(r) for r in metadata.requires(req.name) or ()]
            except metadata.PackageNotFoundError:
                continue
        return seen

    core = closure([Requirement(r) for r in PYPROJECT["project"]["dependencies"]])
    extras = {
        Requirement(r).name.lower().replace("_", "-")
        for reqs in PYPROJECT["project"]["optional-dependencies"].values()
        for r in reqs
    }
    modules = set()
    for module, dists in metadata.packages_distributions().items():
        names = {d.lower().replace("_", "-") for d in dists}
        if names & (extras - core) and not names & core and module.isidentifier():
            modules.add(module)
    return sorted(modules)


def test_the_demo_imports_nothing_of_the_extras():
    blocked = _extras_only_modules()
    assert {"ray", "torchrl", "tianshou", "pandapower", "sphinx", "pytest", "tensorboard"} <= set(
        blocked
    )
    code = (
        "import sys\n"
        f"BLOCKED = set({blocked!r})\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.partition('.')[0] in BLOCKED:\n"
        "            raise ModuleNotFoundError(f'{name} is an extra', name=name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "import agents.demo\n"
        "assert not BLOCKED & set(sys.modules), BLOCKED & set(sys.modules)\n"
        "sys.argv = ['demo', '--help']\n"
        "agents.demo.main()\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "--steps" in done.stdout


def test_make_demo_installs_the_core_only_and_make_test_every_extra():
    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = re.search(r"^\$\(DEMO_STAMP\):.*\n((?:\t.*\n)+)", make, flags=re.MULTILINE)
    assert recipe is not None
    assert "[" not in recipe.group(1) and "-e .\n" in recipe.group(1)
    # the root as the package dir: the editable install is a .pth file, built without a warning
    assert PYPROJECT["tool"]["setuptools"]["package-dir"] == {"": "."}
    assert re.search(r"^demo: \$\(DEMO_STAMP\)$", make, flags=re.MULTILINE)
    full = re.search(r"^\$\(STAMP\):.*\n((?:\t.*\n)+)", make, flags=re.MULTILINE)
    installed = re.search(r'"\.\[([\w,]+)\]"', full.group(1))
    assert set(installed.group(1).split(",")) == set(PYPROJECT["project"]["optional-dependencies"])
    assert re.search(r"^test: lint$", make, flags=re.MULTILINE)
    assert re.search(r"^lint: \$\(STAMP\)$", make, flags=re.MULTILINE)
    # both install torch first, from the pinned CPU wheel
    for body in (recipe.group(1), full.group(1)):
        first = body.splitlines()[0]
        assert first.endswith("-c constraints.txt torch==2.13.0"), first
    assert "torch==2.13.0" in (ROOT / "constraints.txt").read_text(encoding="utf-8").split()


def test_tensorboard_is_the_tensorboard_extra_only():
    core = {Requirement(r).name for r in PYPROJECT["project"]["dependencies"]}
    assert "tensorboard" not in core
    extra = PYPROJECT["project"]["optional-dependencies"]["tensorboard"]
    assert [Requirement(r).name for r in extra] == ["tensorboard"]


def test_make_demo_removes_only_torchs_own_cpp_unit_tests():
    import torch

    make = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = re.search(r"^\$\(DEMO_STAMP\):.*\n((?:\t.*\n)+)", make, flags=re.MULTILINE)
    lines = recipe.group(1).splitlines()
    assert lines[1] == "\t$(PRUNE_TORCH)"  # right after torch, before the package
    prune = re.search(r"^PRUNE_TORCH = .*\\\n\t&& rm -rf (.+)$", make, flags=re.MULTILINE)
    here = Path(torch.__file__).parent
    removed = [p for pattern in prune.group(1).split() for p in here.glob(pattern)]
    if not removed:
        pytest.skip("this venv's torch has no C++ unit tests (make demo removed them)")
    assert here / "test" in removed and here / "bin" / "test_api" in removed
    files = [f for p in removed for f in ([p] if p.is_file() else p.rglob("*"))]
    assert files and (here / "bin" / "torch_shm_manager") not in files
    # programs and test data: no module, no library torch loads
    assert not [f for f in files if f.suffix in (".py", ".so") or ".so." in f.name]


@pytest.mark.parametrize(
    "env_id, kwargs",
    [
        ("fdia_env/SparseAttack-v0", {"action": "sequential", "budget": 6, "horizon": 2}),
        ("fdia_env/SensorGameAttacker-v0", {"action": "sequential"}),
    ],
)
def test_the_sequential_formats_return_new_info_arrays_at_every_decision(env_id, kwargs):
    """Gymnasium's checker (1.3+) warns on an info array shared by two steps: the demo's env."""
    from fdia_env import scenarios
    from fdia_env.tasks.task import make_pinned

    if env_id == "fdia_env/SparseAttack-v0":  # the demo's instance
        kwargs = {**kwargs, "scenario": scenarios.get("ch4-random", seed=5)}
    env = make_pinned(env_id, None, kwargs)
    _, info = env.reset(seed=0)
    kept, values = [info], [{k: np.copy(v) for k, v in info.items()}]
    for _ in range(8):
        legal = np.flatnonzero(info["action_mask"])
        _, _, term, trunc, info = env.step(int(legal[-1]))  # a sensor while one is legal
        kept.append(info)
        values.append({k: np.copy(v) for k, v in info.items()})
        if term or trunc:
            break
    assert len(kept) >= 3
    shared = [
        (i, j, key)
        for i in range(len(kept))
        for j in range(i + 1, len(kept))
        for key in kept[i].keys() & kept[j].keys()
        if isinstance(kept[i][key], np.ndarray) and np.shares_memory(kept[i][key], kept[j][key])
    ]
    assert shared == []
    for info, value in zip(kept, values, strict=True):  # what a user kept did not change
        for key, v in value.items():
            np.testing.assert_array_equal(info[key], v)
