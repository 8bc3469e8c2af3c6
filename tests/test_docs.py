"""The documentation site builds without warnings, covers every env and public function, and
its tutorials run."""

import importlib
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from fdia_env.registration import GYM_IDS

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
import generate_pages  # noqa: E402

# tutorials that need an optional extra: skipped without it (CI installs every extra)
NEEDS = {"rllib": "ray.rllib"}
BASELINE_PACKAGES = [
    "baselines.sparse",
    "baselines.covariance",
    "baselines.game",
    "baselines.detection",
]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """Build the site from scratch with warnings as errors (what ``make docs`` runs)."""
    sphinx = pytest.importorskip("sphinx.cmd.build")
    out = tmp_path_factory.mktemp("html")
    status = sphinx.build_main(
        ["-E", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(out)]
    )
    assert status == 0, "sphinx-build reported warnings or errors (see the captured output)"
    return out


def test_every_env_module_and_gym_id_has_a_page_with_its_image(site):
    for name in generate_pages.ENV_MODULES:
        page = (site / "environments" / f"{name}.html").read_text(encoding="utf-8")
        assert f"_images/{name}.png" in page  # Sphinx copies the rendered image there
        assert (site / "_images" / f"{name}.png").stat().st_size > 10_000
        for section in ("Action Space", "Observation Space", "Rewards", "Version History"):
            assert section in page, (name, section)
    pages = "".join(p.read_text(encoding="utf-8") for p in (site / "environments").glob("*.html"))
    for env_id in GYM_IDS:
        assert env_id in pages, env_id


def test_every_public_function_of_baselines_is_in_the_api_reference(site):
    for package in BASELINE_PACKAGES:
        module = importlib.import_module(package)
        page = (site / "api" / f"{package}.html").read_text(encoding="utf-8")
        for name in module.__all__:
            if callable(getattr(module, name)):
                assert f'<span class="sig-name descname"><span class="pre">{name}</span>' in page, (
                    f"{package}.{name} missing"
                )


def test_the_literature_map_names_only_functions_that_exist():
    text = (DOCS / "literature.md").read_text(encoding="utf-8")
    names = re.findall(r"`((?:fdia_env|baselines)\.[\w.]+)`(?:, `(\w+)`)*", text)
    rows = [line for line in text.splitlines() if line.startswith("| ") and "`" in line]
    checked = 0
    for row in rows:
        cell = row.split("|")[3]
        refs = re.findall(r"`([\w.]+)`", cell)
        base = None
        for ref in refs:
            if "." in ref:
                base, attr = ref.rsplit(".", 1)
            elif base is None:
                continue
            else:
                attr = ref
            try:
                module = importlib.import_module(f"{base}.{attr}")
            except ModuleNotFoundError:
                module = importlib.import_module(base)
                assert hasattr(module, attr), f"{base}.{attr} does not exist"
            checked += 1
    assert checked >= 30 and names


@pytest.mark.parametrize("script", sorted((DOCS / "tutorials").glob("*.py")), ids=lambda p: p.stem)
def test_tutorial_runs(script):
    if script.stem in NEEDS:
        needs = NEEDS[script.stem]
        pytest.importorskip(needs, reason=f"the {script.stem} tutorial needs {needs}")
    # the checkout's own packages first (a script's sys.path[0] is its folder, not the root)
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    env = {**os.environ, "FDIA_TUTORIAL_QUICK": "1", "OPENBLAS_NUM_THREADS": "1"}
    env["PYTHONPATH"] = path
    done = subprocess.run(
        [sys.executable, str(script)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip()


def test_every_tutorial_script_has_a_page():
    for script in (DOCS / "tutorials").glob("*.py"):
        page = DOCS / "tutorials" / f"{script.stem}.md"
        assert f"{script.stem}.py" in page.read_text(encoding="utf-8")
        assert script.stem in (DOCS / "tutorials" / "index.md").read_text(encoding="utf-8")
    assert inspect.isfunction(generate_pages.env_page)
