"""The README: its examples and commands run and print what it shows (warnings as errors), its
table of environments is the package's, and it stays a front page.

The guide pages' Python examples run here too (``docs/environments/index.md``,
``docs/guide/*.md``, ``docs/benchmarks.md``).
"""

import contextlib
import importlib
import io
import re
import shlex
import struct
import tomllib
from pathlib import Path

import pytest
from conftest import command_output, printed_by

import fdia_env
from fdia_env.registration import AGENTS, ENVS, GYM_IDS, get_env, vector_ids

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
GUIDE_PAGES = [
    ROOT / "docs" / "environments" / "index.md",
    *sorted((ROOT / "docs" / "guide").glob("*.md")),
    ROOT / "docs" / "benchmarks.md",
]


def section(text: str, title: str) -> str:
    """The body of the ``## title`` section."""
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_quickstart_prints_the_output_shown_in_the_readme():
    quickstart = section(README, "Quickstart")
    code = re.search(r"```python\n(.*?)```", quickstart, flags=re.S).group(1)
    shown = re.search(r"Output:\n\n```\n(.*?)```", quickstart, flags=re.S).group(1)
    assert printed_by(code, "README quickstart") == shown


def test_the_quickstart_uses_the_newest_version_of_each_env_it_names():
    # an older id makes Gymnasium warn that it is out of date (printed_by fails on it too)
    newest = {}
    for env_id in GYM_IDS:
        name, version = env_id.rsplit("-v", 1)
        newest[name] = max(newest.get(name, 0), int(version))
    for name, version in re.findall(r"(fdia_env/\w+)-v(\d+)", section(README, "Quickstart")):
        assert int(version) == newest[name], f"{name}-v{version}: the newest is v{newest[name]}"


def test_the_score_command_prints_the_output_shown(tmp_path):
    score = section(README, "Score on a benchmark task")
    command = re.search(r"```bash\n(python -m agents\.bench score [^\n]*)\n```", score).group(1)
    shown = re.search(r"```bash\n.*?```\n\n```text\n(.*?)```", score, flags=re.S).group(1)
    assert command_output(command, tmp_path) == shown


def test_the_tasks_example_prints_the_output_shown():
    score = section(README, "Score on a benchmark task")
    code = re.search(r"```python\n(.*?)```", score, flags=re.S).group(1)
    shown = re.search(r"```python\n.*?```\n\n```text\n(.*?)```", score, flags=re.S).group(1)
    assert printed_by(code, "README benchmark tasks") == shown


def test_every_train_command_is_accepted_by_train_py():
    import train

    commands = re.findall(r"^python train\.py ([^#\n]*)", section(README, "Train"), flags=re.M)
    assert len(commands) == 4
    for command in commands:
        config = train.parse(shlex.split(command))
        assert type(config).__name__ in {"TrainConfig", "GameConfig"}, command


def _env_table() -> list[list[str]]:
    body = section(README, "Environments")
    rows = [line for line in body.splitlines() if line.startswith("| `")]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows]


def _ticked(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def test_the_environment_table_lists_every_registered_env_as_it_is():
    rows = _env_table()
    assert len(rows) == len(ENVS) == 9
    by_module = {entry.module: name for name, entry in ENVS.items()}
    seen = set()
    for module, ids, players, formats, vector in rows:
        (path,) = _ticked(module)
        assert path in by_module, f"{path} is not a registered env module"
        name = by_module[path]
        entry, seen = get_env(name), seen | {name}
        parallel = importlib.import_module(path).parallel_env()
        # the Gymnasium ids: exactly the entry's views, each registered by `import fdia_env`
        assert set(_ticked(ids)) == set(entry.views.values()), name
        # players: every agent of the default env and of each view, nothing else
        listed = {p.strip() for p in players.split(",")}
        assert set(parallel.possible_agents) | set(entry.views) <= listed <= set(AGENTS), name
        # the quoted action formats are values the module's `action=` option accepts
        for option in re.findall(r'`"(\w+)"`', formats):
            env = importlib.import_module(path).parallel_env(action=option)
            assert env.possible_agents, (name, option)
        # the native vector env: the backends of the views that have one
        with_vector = [a for a in entry.views if entry.has_vector(a)]
        if vector == "–":
            assert not with_vector, name
            continue
        backends, _, only = vector.partition(" (")
        assert tuple(b.strip() for b in backends.split(",")) == entry.backends, name
        assert (
            only.rstrip(")").split(", ") == with_vector
            if only
            else with_vector == list(entry.views)
        ), name
        for gym_id in (entry.views[a] for a in with_vector):
            assert all(gym_id in vector_ids(b) for b in entry.backends), gym_id
    assert seen == set(ENVS)
    counts = section(README, "Environments")
    assert f"{len(GYM_IDS)} ids" in counts.replace("twelve", "12")
    assert "Nine PettingZoo modules" in counts and len(ENVS) == 9


def test_the_readme_stays_a_front_page():
    lines, words = README.count("\n"), len(README.split())
    assert lines <= 200 and words <= 1500, (lines, words)
    for title in ("Install", "Quickstart", "Environments", "Train", "Score on a benchmark task"):
        assert f"\n## {title}\n" in README, title
    for extra in ("grid", "rllib", "clients", "tensorboard", "docs", "dev"):
        assert f"`{extra}`" in section(README, "Install"), extra
    install = section(README, "Install")
    for line in ("pip install torch==2.13.0", "pip install -c constraints.txt .", '".[grid]"'):
        assert line in install, line
    assert "torch==2.13.0" in (ROOT / "constraints.txt").read_text()  # the pin the page names
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for name in re.findall(r"`(fdia-[a-z]+)`", install):
        assert name in scripts, name
    assert re.search(r"```bibtex\n@software\{fdia_env,.*?\n\}\n```", README, flags=re.S)
    assert not re.search(r"20\d\d-\d\d-\d\d", README), "a dated sentence"
    assert fdia_env.__version__ in section(README, "Citing")


def test_the_readme_figure_is_a_committed_png():
    (figure,) = re.findall(r"!\[[^\]]+\]\(([^)]+\.png)\)", README)
    data = (ROOT / figure).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    assert width >= 400 and height >= 200 and len(data) > 10_000


def test_every_readme_link_names_a_file_that_exists():
    links = re.findall(r"\]\(((?:docs/|CHANGELOG)[^)#]+)(?:#[^)]*)?\)", README)
    assert len(links) >= 12
    for link in links:
        assert (ROOT / link).is_file(), f"README links to {link}, which does not exist"


def test_the_guide_pages_hold_their_examples():
    assert sum(len(python_blocks(p.read_text(encoding="utf-8"))) for p in GUIDE_PAGES) >= 11


@pytest.mark.parametrize(
    "page", [ROOT / "README.md", *GUIDE_PAGES], ids=lambda p: str(p.relative_to(ROOT))
)
def test_every_python_block_runs(page):
    for code in python_blocks(page.read_text(encoding="utf-8")):
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(code, str(page.relative_to(ROOT)), "exec"), {})
