"""The README's and the guide pages' Python examples run, and the quickstart prints exactly the
output shown.

The README is an overview; the sections it used to hold live in the documentation site
(``docs/environments/index.md``, ``docs/guide/*.md``, ``docs/benchmarks.md``), verbatim, and
their examples are run here as they were when they were part of the README.
"""

import contextlib
import io
import re
from pathlib import Path

import pytest
from conftest import printed_by

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
# the pages holding what was the README's reference sections (examples with real output)
GUIDE_PAGES = [
    ROOT / "docs" / "environments" / "index.md",
    *sorted((ROOT / "docs" / "guide").glob("*.md")),
    ROOT / "docs" / "benchmarks.md",
]


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_quickstart_prints_the_output_shown_in_the_readme():
    quickstart = README.split("## Quickstart", 1)[1]
    code = re.search(r"```python\n(.*?)```", quickstart, flags=re.S).group(1)
    shown = re.search(r"Output:\n\n```\n(.*?)```", quickstart, flags=re.S).group(1)
    assert printed_by(code, "README quickstart") == shown


def test_every_readme_link_into_the_docs_names_a_page_that_exists():
    links = re.findall(r"\]\((docs/[^)#]+)(?:#[^)]*)?\)", README)
    assert len(links) >= 12
    for link in links:
        assert (ROOT / link).is_file(), f"README links to {link}, which does not exist"


def test_the_guide_pages_hold_every_example_the_readme_had():
    # 1 quickstart in the README, 11 examples with their output in the guide pages
    assert len(python_blocks(README)) >= 1
    assert sum(len(python_blocks(p.read_text(encoding="utf-8"))) for p in GUIDE_PAGES) >= 11


@pytest.mark.parametrize(
    "page", [ROOT / "README.md", *GUIDE_PAGES], ids=lambda p: str(p.relative_to(ROOT))
)
def test_every_python_block_runs(page):
    for code in python_blocks(page.read_text(encoding="utf-8")):
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(code, str(page.relative_to(ROOT)), "exec"), {})
