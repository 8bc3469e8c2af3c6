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


# A citation is a path-like token naming a Markdown document; URLs and format strings (a "{" or
# "/" just before the name) are not citations. (Source paths are left out: the guides name files
# a user is to create, such as a new env module.)
_CITED = re.compile(r"(?<![\w/.{}:-])((?:\.\./)*[\w][\w./-]*\.md)(?![\w-])")
_TEXT_SUFFIXES = {".py", ".md", ".toml", ".txt", ".cfg", ".ini", ".yml", ".yaml", ".rst", ".sh"}


def _tracked() -> list[str]:
    try:
        return subprocess.run(
            ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")


def _tracked_text_files() -> list[Path]:
    return [
        ROOT / name
        for name in _tracked()
        if (ROOT / name).suffix in _TEXT_SUFFIXES or name == "Makefile"
    ]


def _generated_at_build(path: str) -> bool:
    """Pages that docs/_ext/generate_pages.py writes during the build (not tracked)."""
    name = Path(path).name
    if path.startswith(("docs/api/", "api/")):
        return True
    env_pages = {f"{module}.md" for module in generate_pages.ENV_MODULES}
    return "environments" in path and name in env_pages


def test_no_tracked_file_cites_a_file_the_repository_does_not_contain():
    """Every Markdown file or project path named in code, tests and docs is in the repository.

    The formulas and literature values are cited as docs/math.md and docs/references.md; a
    citation of a document that is not shipped (a private specification, a renamed page) fails.
    """
    files = _tracked_text_files()
    assert len(files) > 100
    # a name may be given relative to the citing file, to the root, or to a folder that holds it
    # (``DOCS / "reproduction.md"``, "guide/clients.md" from the docs' index)
    tails = {"/".join(Path(n).parts[i:]) for n in _tracked() for i in range(len(Path(n).parts))}
    missing = []
    for file in files:
        text = file.read_text(encoding="utf-8", errors="replace")
        for number, line in enumerate(text.splitlines(), 1):
            for cited in _CITED.findall(line):
                cited = cited.rstrip(".")
                if _generated_at_build(cited):
                    continue
                if (file.parent / cited).exists() or cited.lstrip("./") in tails:
                    continue
                missing.append(f"{file.relative_to(ROOT)}:{number}: {cited}")
    assert not missing, "citations of files the repository does not contain:\n" + "\n".join(missing)


def test_the_math_and_literature_pages_keep_the_cited_section_numbers():
    """Every "docs/math.md §x.y" / "docs/references.md §x" cited has its labelled section."""
    labels = {
        "math": set(re.findall(r"^\(math-([\d-]+)\)=$", _read("math.md"), re.M)),
        "references": set(re.findall(r"^\(references-([\d-]+)\)=$", _read("references.md"), re.M)),
    }
    assert {"1", "2-1", "2-2", "2-3", "2-4", "3", "4", "5", "6", "7"} <= labels["math"]
    assert {"2", "3", "4", "5"} <= labels["references"]
    cited = re.compile(r"docs/(math|references)\.md §\s?([\d.]*\d)")
    wrong = []
    for file in _tracked_text_files():
        text = file.read_text(encoding="utf-8", errors="replace")
        for page, section in cited.findall(text):
            if section.replace(".", "-") not in labels[page]:
                wrong.append(f"{file.relative_to(ROOT)}: docs/{page}.md §{section}")
    assert not wrong, wrong


def _read(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def test_no_user_facing_text_names_a_tracker_entry():
    """A user has no access to the project's tracker: help texts, docstrings, benchmarks and
    pages state a target and its reason, never "issue 13's target" or "Targets (issue 8)"."""
    tracker = re.compile(r"\bissues?\s*#?\d+|\(issues?\)|\bthe issue\b|\bissue's", re.IGNORECASE)
    found = []
    for file in _tracked_text_files():
        text = file.read_text(encoding="utf-8", errors="replace")
        for number, line in enumerate(text.splitlines(), 1):
            if tracker.search(line) and file.name != "test_docs.py":
                found.append(f"{file.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)
