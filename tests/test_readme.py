"""The README's Python examples run, and the quickstart prints exactly the output shown."""

import contextlib
import io
import re
from pathlib import Path

README = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8")


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_quickstart_prints_the_output_shown_in_the_readme():
    quickstart = README.split("## Quickstart", 1)[1]
    code = re.search(r"```python\n(.*?)```", quickstart, flags=re.S).group(1)
    shown = re.search(r"Output:\n\n```\n(.*?)```", quickstart, flags=re.S).group(1)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README quickstart", "exec"), {})
    assert out.getvalue() == shown


def test_every_python_block_runs():
    python_blocks = blocks("python")
    assert len(python_blocks) >= 2
    for code in python_blocks:
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(code, "README", "exec"), {})
