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
        assert (site / "_images" / f"{name}.png").stat().st_size > 5_000  # a figure, not a blank
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
    # every ```text block of the tutorial's page is what the script prints, in order
    page = (DOCS / "tutorials" / f"{script.stem}.md").read_text(encoding="utf-8")
    expected = [line for block in _checked_outputs(page) for line in block if line.strip()]
    printed = [line for line in done.stdout.splitlines() if line.strip()]
    _assert_printed_in_order(expected, printed)


def _checked_outputs(page: str) -> list[list[str]]:
    """The lines of every fenced ``text`` block (the page's checked outputs)."""
    return [b.splitlines() for b in re.findall(r"^```text\n(.*?)^```", page, re.S | re.M)]


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _same_output(expected: str, printed: str) -> bool:
    """Same text, and numbers equal to 1e-4 relative (or 1e-9 absolute: a printed 3.6e-12)."""
    if _NUMBER.sub("#", expected).split() != _NUMBER.sub("#", printed).split():
        return False
    pairs = zip(_NUMBER.findall(expected), _NUMBER.findall(printed), strict=True)
    return all(abs(float(a) - float(b)) <= 1e-9 + 1e-4 * abs(float(a)) for a, b in pairs)


def _assert_printed_in_order(expected: list[str], printed: list[str]) -> None:
    at = 0
    for line in expected:
        hits = [i for i in range(at, len(printed)) if _same_output(line, printed[i])]
        assert hits, f"the page shows {line!r}, the script no longer prints it:\n" + "\n".join(
            printed
        )
        at = hits[0] + 1


def test_the_output_check_compares_numbers_not_just_text():
    assert _same_output("tr P = 0.370028  attacks ((2, 0))", "tr P = 0.370029  attacks ((2, 0))")
    assert _same_output("gap 3.6e-12", "gap 1.1e-13")
    assert not _same_output("tr P = 0.370028", "tr P = 0.371028")
    assert not _same_output("SFS 0.032786", "DP  0.032786")
    with pytest.raises(AssertionError, match="no longer prints"):
        _assert_printed_in_order(["b 2", "a 1"], ["a 1", "b 2"])


def test_every_worked_tutorial_shows_its_output():
    for name in ("sparse_attacker", "sensor_game", "detection_game", "own_system", "vector_envs"):
        page = (DOCS / "tutorials" / f"{name}.md").read_text(encoding="utf-8")
        assert len(_checked_outputs(page)) >= 1, name
        prose = [p for p in page.split("\n\n") if not p.startswith(("```", "#", ":"))]
        assert sum(len(p) for p in prose) > 1500, f"{name}: a page of prose, not a bare include"


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
# pages a command writes where it is told (the leaderboard runner's --page and its default
# leaderboard.md beside --out), named by its code, docs and tests: outputs, not citations
_WRITTEN_PAGES = {"leaderboard.md", "page.md", "plain.md", "p.md"}


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


def test_no_page_the_build_writes_is_tracked():
    """Regression: a generated env page was committed (docs/environments/sparse_attack_v1.md).

    The build rewrites those pages from the env modules' docstrings and renders their images into
    docs/_static/envs/ (ignored); a tracked copy goes stale and links an image that is not there.
    """
    env_pages = {f"docs/environments/{module}.md" for module in generate_pages.ENV_MODULES}
    generated = [
        name
        for name in _tracked()
        if name in env_pages or (name.startswith("docs/api/") and name != "docs/api/index.md")
    ]
    assert not generated, f"generated pages tracked by git: {generated}"


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
                if Path(cited).name in _WRITTEN_PAGES:
                    continue
                if _generated_at_build(cited) or _generated_at_build(
                    str((file.parent / cited).relative_to(ROOT))
                ):
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


@pytest.mark.parametrize("name", generate_pages.ENV_MODULES)
def test_env_page_usage_snippets_run(name):
    """The AEC, parallel and Gymnasium-view snippets of every env page run as printed."""
    section = generate_pages.usage_section(name)
    blocks = re.findall(r"^```python\n(.*?)^```", section, re.S | re.M)
    views = generate_pages.get_env(name).views
    assert len(blocks) == 2 + len(views)
    assert ("### Gymnasium view" in section) == bool(views)
    for code in blocks:
        exec(compile(code, f"<{name} page>", "exec"), {})


def test_env_page_header_gives_observation_spaces_and_renders_no_raw_roles(tmp_path):
    page = generate_pages.env_page("sparse_attack_v0", tmp_path)
    assert "| `attacker` observation space | `Dict`: `action_mask`: `Box` shape `(8,)`" in page
    assert "| `fdia_env/SparseAttack-v0` observation space | `Box` shape `(5,)`, `float32`" in page
    assert 'info["action_mask"]' in page and "action_masks()" in page
    page = generate_pages.env_page("detection_game_v0", tmp_path)
    assert ":class:`" not in page and ":mod:`" not in page
    assert "{py:class}`~fdia_env.defenses.detector.ThresholdDetector`" in page
    assert "{ref}`math §3 <math-3>`" in page and "docs/math.md" not in page


def test_link_check_reports_a_missing_anchor_and_a_missing_page(tmp_path, caplog):
    import local_links

    (tmp_path / "a.html").write_text(
        '<p id="here"><a href="#here">ok</a> <a href="b.html#gone">x</a> '
        '<a href="c.html">y</a> <a href="https://example.org/#z">ext</a></p>',
        encoding="utf-8",
    )
    (tmp_path / "b.html").write_text('<p id="there"></p>', encoding="utf-8")
    app = type("App", (), {"outdir": str(tmp_path), "builder": type("B", (), {"format": "html"})})
    with caplog.at_level("WARNING"):
        local_links.check_local_links(app, None)
    messages = [r.getMessage() for r in caplog.records]
    assert any("b.html#gone (no such anchor)" in m for m in messages), messages
    assert any("c.html (no such file)" in m for m in messages), messages
    assert len(messages) == 2, messages


def test_docstring_citations_become_links_except_in_literals_and_doctests():
    import local_links

    lines = [
        "The payoff of docs/math.md §5, and docs/references.md §4's table.",
        "``x = 1 (docs/math.md §2)`` is literal; after it, docs/math.md §2.1 is not.",
        ">>> f()  # docs/math.md §3",
    ]
    local_links.link_citations(None, "function", "f", None, {}, lines)
    assert lines == [
        "The payoff of :ref:`docs/math.md §5 <math-5>`, and "
        ":ref:`docs/references.md §4 <references-4>`'s table.",
        "``x = 1 (docs/math.md §2)`` is literal; after it, "
        ":ref:`docs/math.md §2.1 <math-2-1>` is not.",
        ">>> f()  # docs/math.md §3",
    ]


def test_site_pages_link_back_from_the_source_and_show_usage(site):
    # the source of a re-exported function links back to its one indexed entry (the build's link
    # check fails on a broken one; here: the back-links are there at all)
    source = (site / "_modules" / "fdia_env" / "systems" / "tracking.html").read_text("utf-8")
    assert 'class="viewcode-back" href="../../../api/fdia_env.systems.html#fdia_env.systems.' in (
        source
    )
    page = (site / "environments" / "sparse_attack_v0.html").read_text(encoding="utf-8")
    assert "Gymnasium view" in page and "agent_iter" in page and ":class:" not in page
    assert 'href="../math.html#math-4"' in page


def test_a_rebuild_rewrites_the_highlighted_sources(tmp_path):
    import local_links

    stale = tmp_path / "_modules" / "fdia_env" / "systems" / "tracking.html"
    stale.parent.mkdir(parents=True)
    stale.write_text('<a class="viewcode-back" href="../gone.html#x">[docs]</a>', "utf-8")
    app = type("App", (), {"outdir": str(tmp_path), "builder": type("B", (), {"format": "html"})})
    local_links.fresh_source_pages(app)
    assert not (tmp_path / "_modules").exists()
