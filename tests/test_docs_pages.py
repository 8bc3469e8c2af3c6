"""The docs' front pages: the landing page's example, the getting-started page's commands (run
at the page's budget, printing what the page shows, warnings as errors) and the gallery of every
environment; the site's footer; no dated sentences in the README, the guides or the code."""

import re
import subprocess
from pathlib import Path

import pytest
from conftest import command_output, printed_by

from fdia_env.registration import ENVS, GYM_IDS

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _read(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def _code_and_output(text: str, language: str) -> list[tuple[str, str]]:
    """Each ``language`` block followed by the ``text`` block that shows its output."""
    block = r"((?:[^`]|`(?!``))*?)"  # a block's body: no fence inside it
    pattern = rf"^```{language}\n{block}^```\n\n```text\n{block}^```"
    return re.findall(pattern, text, flags=re.S | re.M)


def _timing_free(text: str) -> str:
    """Output with its wall times (``in 17 s``) masked: they vary from run to run."""
    return re.sub(r"\bin \d+(?:\.\d+)? s\b", "in <t> s", text)


def test_the_landing_page_example_prints_what_it_shows():
    ((code, shown),) = _code_and_output(_read("index.md"), "python")
    assert printed_by(code, "docs/index.md") == shown
    assert "return 0.032786, optimum 0.032786" in shown  # the literature's tr P = 0.0328


def test_the_landing_page_has_a_picture_and_the_way_in():
    page = _read("index.md")
    (figure,) = re.findall(r"!\[[^\]]+\]\(([^)]+\.png)\)", page)
    assert (DOCS / figure).stat().st_size > 10_000
    assert "getting_started" in page and "environments/gallery.md" in page
    assert "make demo" not in page.split("```{toctree}")[0]  # a command cut off at the edge
    words = {9: "nine", 12: "twelve"}
    assert (
        f"the {words[len(ENVS)]} PettingZoo modules and {words[len(GYM_IDS)]} Gymnasium ids" in page
    )


def test_the_getting_started_page_takes_four_steps_in_order():
    headings = re.findall(r"^## (.+)$", _read("getting_started.md"), flags=re.M)
    assert headings == [
        "1. Install",
        "2. A first environment",
        "3. A first training run",
        "4. A first score on a benchmark task",
    ]


def test_the_getting_started_first_env_prints_what_it_shows():
    ((code, shown),) = _code_and_output(_read("getting_started.md"), "python")
    assert printed_by(code, "docs/getting_started.md") == shown


def test_the_getting_started_commands_print_what_the_page_shows(tmp_path):
    # the training run, then the score of its run folder, as a new user runs them
    commands = _code_and_output(_read("getting_started.md"), "bash")
    assert [c.split()[1] for c, _ in commands] == ["train.py", "-m"]
    for command, shown in commands:
        printed = command_output(command.strip(), tmp_path)
        assert max(len(line) for line in command.splitlines()) <= 90  # fits the page's width
        assert _timing_free(printed.strip("\n")) == _timing_free(shown.strip("\n")), command
    assert (tmp_path / "runs" / "first" / "config.json").is_file()


def test_the_timing_mask_leaves_every_other_number():
    line = "MaskablePPO attacker on fdia_env/SparseAttack-v2, 2048 steps in 17 s (seed 0)"
    assert _timing_free(line) == line.replace("17 s", "<t> s")
    assert _timing_free("0.0125274 ± 0 in 3.5 s") == "0.0125274 ± 0 in <t> s"


def test_the_gallery_shows_every_environment_once():
    page = _read("environments/gallery.md")
    names = re.findall(r"^## \[`(\w+)`\]\((\w+)\.md\)$", page, flags=re.M)
    assert [n for n, _ in names] == list(ENVS) and all(n == m for n, m in names)
    images = re.findall(r"!\[[^\]]+\]\(\.\./_static/envs/(\w+)\.png\)", page)
    assert images == list(ENVS)
    for name, entry in ENVS.items():
        section = page.split(f"## [`{name}`]")[1].split("\n## ")[0]
        for gym_id in entry.views.values():
            assert f"`{gym_id}`" in section, (name, gym_id)


def test_the_footer_names_the_project():
    conf = _read("conf.py")
    (holder,) = re.findall(r'^copyright = "([^"]+)"', conf, flags=re.M)
    assert "fdia_env" in holder


DATED = re.compile(r"20\d\d-\d\d-\d\d")


def _tracked(*paths: str) -> list[Path]:
    try:
        names = subprocess.run(
            ["git", "ls-files", *paths], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    return [ROOT / n for n in names if n.endswith((".py", ".md"))]


def test_no_dated_sentence_in_the_readme_the_guides_or_the_code():
    # run dates belong to the results pages (docs/results/, docs/benchmarks.md,
    # docs/benchmark.md, docs/reproduction.md) and history to CHANGELOG.md
    results = ("docs/results/", "docs/benchmarks.md", "docs/benchmark.md", "docs/reproduction.md")
    files = [
        f
        for f in _tracked("README.md", "docs", "fdia_env", "baselines", "agents", "train.py")
        if not str(f.relative_to(ROOT)).startswith(results)
    ]
    assert len(files) > 50 and ROOT / "docs" / "guide" / "sparse.md" in files
    dated = [
        f"{f.relative_to(ROOT)}:{i}: {line.strip()}"
        for f in files
        for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1)
        if DATED.search(line)
    ]
    assert not dated, "\n".join(dated)
