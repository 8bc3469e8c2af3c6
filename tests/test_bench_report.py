"""benchmarks/report.py: the generated section of the benchmarks page is replaced, not appended."""

import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("bench_report", ROOT / "benchmarks" / "report.py")
report = sys.modules["bench_report"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(report)


def test_rerun_replaces_every_figure_and_keeps_the_prose(tmp_path):
    page = tmp_path / "benchmarks.md"
    page.write_text("# Performance\n\nProse kept.\n")
    bench = report.BENCHES[0]
    report.write_page(page, report.section([(bench, "python x.py", "rate 1,000 steps/s")], False))
    first = page.read_text()
    assert first.startswith("# Performance\n") and "Prose kept." in first
    assert "rate 1,000 steps/s" in first and "machine:" in first
    report.write_page(page, report.section([(bench, "python x.py", "rate 2,000 steps/s")], False))
    second = page.read_text()
    assert "rate 2,000 steps/s" in second and "1,000" not in second  # nothing stale survives
    assert second.count(report.BEGIN) == 1 and second.count(report.END) == 1
    assert "Prose kept." in second


def test_a_failing_benchmark_is_reported_not_hidden(tmp_path, monkeypatch):
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "boom.py").write_text("import sys\nprint('partial')\nsys.exit(3)\n")
    monkeypatch.setattr(report, "ROOT", tmp_path)
    bench = report.Bench("boom", "boom.py", (), (), "a failing script")
    _, out = report.run(bench, quick=False, timeout=60)
    assert out.startswith("(failed with exit status 3)") and "partial" in out


def test_a_script_that_exits_1_keeps_all_its_figures(tmp_path, monkeypatch):
    # a script that exits 1 for a missed target (seq_throughput.py) and warns on stderr: every
    # line it printed stays in the page (the summary row is parsed from them), then its errors
    (tmp_path / "benchmarks").mkdir()
    script = (
        "import sys\nfor i in range(30): print(f'figure {i}')\n"
        "for i in range(30): print(f'warning {i}', file=sys.stderr)\nsys.exit(1)\n"
    )
    (tmp_path / "benchmarks" / "miss.py").write_text(script)
    monkeypatch.setattr(report, "ROOT", tmp_path)
    _, out = report.run(report.Bench("miss", "miss.py", (), (), "x"), quick=False, timeout=60)
    assert out.startswith("(failed with exit status 1)\nfigure 0\n")
    assert "figure 29" in out and "warning 29" in out and "warning 14" not in out


VECTOR_OUTPUT = """machine: Some CPU, x86_64, 2 cores; 2026-01-01 00:00 UTC; clock: cpu
fdia_env from .
     B  native (env-steps/s)  SyncVectorEnv  CartPole native  native/Sync  native/CartPole
  1024             8,000,000         20,000       10,000,000       400.0x            0.80x
 65536            50,000,000            nan       25,000,000         nanx            2.00x
targets: native/Sync >= 50x at B = 1024; native/CartPole >= 1.5x at B = 65536"""


def test_one_machine_line_for_the_whole_run(tmp_path, monkeypatch):
    # the scripts' own "machine:" lines are dropped: the page names the machine once
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "v.py").write_text(f"print({VECTOR_OUTPUT!r})\n")
    monkeypatch.setattr(report, "ROOT", tmp_path)
    bench = report.Bench("v", "v.py", (), (), "vector", report.BENCHES_BY_NAME[2].summary)
    cmd, out = report.run(bench, quick=False, timeout=60)
    assert "machine:" not in out and "fdia_env from" not in out and "2.00x" in out
    text = report.section([(bench, cmd, out), (bench, cmd, out)], False)
    assert text.count("machine:") == 1


def test_the_summary_table_is_rebuilt_from_the_run(tmp_path):
    # every row comes from this run's output, with the reference's rate of the same run; a
    # rerun replaces the table, so a figure of an earlier run cannot survive
    vector = next(b for b in report.BENCHES if b.name == "vector")
    page = tmp_path / "benchmarks.md"
    page.write_text(
        f"# x\n\n## At a glance\n\nProse.\n\n{report.SUMMARY_BEGIN}\n| old | 9.99× | |\n"
        f"{report.SUMMARY_END}\n\n## Next\n"
    )
    table = report.summary_table([(vector, "python benchmarks/vector.py", VECTOR_OUTPUT)], False)
    report.write_page(page, table, report.SUMMARY_BEGIN, report.SUMMARY_END)
    text = page.read_text()
    assert "9.99" not in text and "Prose." in text and text.endswith("## Next\n")
    rows = [line for line in text.splitlines() if line.startswith("| native")]
    assert rows[0].split(" | ")[1:] == [
        "2.00× (50,000,000 env-steps/s)",
        "CartPole native 25,000,000 env-steps/s |",
    ]
    assert "400.0×" in text and "`SyncVectorEnv` 20,000 env-steps/s" in text
    assert "machine:" in text and text.count(report.SUMMARY_BEGIN) == 1
    failed = report.summary_table(
        [(vector, "python benchmarks/vector.py", "(failed with exit status 1)\nboom")], False
    )
    assert "`vector.py` failed in this run" in failed and "2.00" not in failed
    # a script that prints its figures and exits 1 for a missed target keeps them, flagged
    missed = report.summary_table(
        [(vector, "python benchmarks/vector.py", f"(failed with exit status 1)\n{VECTOR_OUTPUT}")],
        False,
    )
    assert "2.00× (50,000,000 env-steps/s) (`vector.py` failed with exit status 1)" in missed


def test_a_run_writes_the_summary_table_above_the_outputs_of_one_page(tmp_path, monkeypatch):
    # one page holds both generated sections, the summary first; the README holds no figures
    page = tmp_path / "benchmarks.md"
    page.write_text("# Performance\n\nProse.\n")
    monkeypatch.setattr(report, "run", lambda b, q, t: (f"python benchmarks/{b.script}", ""))
    assert report.main(["--page", str(page), "--only", "vector"]) == 0
    text = page.read_text()
    assert text.index(report.SUMMARY_BEGIN) < text.index(report.BEGIN) < text.index("Prose.")
    assert text.count(report.SUMMARY_END) == 1 and text.count(report.END) == 1
    assert report.SUMMARY_BEGIN not in (ROOT / "README.md").read_text()


def test_only_reruns_its_benchmarks_and_keeps_the_others_with_their_dates(tmp_path, monkeypatch):
    # --only replaces its blocks and keeps the page's others (a full run replaces all), each
    # kept block and the summary table's header naming the run it came from
    page = tmp_path / "benchmarks.md"
    page.write_text("# Performance\n\nProse.\n")
    rates = {"vector": VECTOR_OUTPUT, "single_view": "view / CartPole-v1: 0.31x"}
    monkeypatch.setattr(
        report, "run", lambda b, q, t: (f"python benchmarks/{b.script}", rates[b.name])
    )
    now = ["2026-01-01 00:00 UTC"]
    monkeypatch.setattr(report, "_now", lambda: now[0])
    args = ["--page", str(page), "--only"]
    assert report.main([*args, "single_view", "vector"]) == 0
    rates["single_view"], now[0] = "view / CartPole-v1: 0.42x", "2026-02-02 00:00 UTC"
    assert report.main([*args, "single_view"]) == 0
    text = page.read_text()
    assert "0.42x" in text and "0.31x" not in text and "2.00x" in text and "Prose." in text
    blocks = report.read_blocks(text)
    assert [(k.bench.name, k.when) for k in blocks] == [
        ("single_view", "2026-02-02 00:00 UTC"),
        ("vector", "2026-01-01 00:00 UTC"),
    ]
    assert "Kept from the run of 2026-01-01 00:00 UTC." in text
    assert "reran single_view; the other blocks are kept" in text
    table = text.split(report.SUMMARY_BEGIN)[1].split(report.SUMMARY_END)[0]
    assert "0.42×" in table and "2.00× (50,000,000 env-steps/s)" in table
    assert "reran the others), the run of 2026-01-01 00:00 UTC: `vector.py`." in table
    # a run of every benchmark keeps nothing
    assert report.section([(blocks[0].bench, "c", "o")], False, kept=None).count("block:") == 1


def test_every_benchmark_of_the_run_names_its_summary_figures():
    # each benchmark contributes rows; an output without its figures says so, never blank
    for bench in report.BENCHES:
        rows = bench.summary("")
        assert rows, bench.name
        table = report.summary_table([(bench, "cmd", "unrelated output")], False)
        assert table.count(f"not in `{bench.script}`'s output") == len(rows), bench.name


FIGURE = re.compile(r"\d(?:[\d,.]*\d)?\s?(?:×|x\b|steps/s|µs|ms\b|%|s\b)")


def test_no_figure_outside_the_generated_sections():
    # the page's figures all lie between the markers that make bench rewrites
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    head, rest = page.split(report.SUMMARY_BEGIN)
    between, rest = rest.split(report.SUMMARY_END)[1].split(report.BEGIN)
    outside = head + between + rest.split(report.END)[1]
    assert FIGURE.findall(outside) == []
    assert FIGURE.findall("took 1.5× and 12 s, 30 %, 165 µs") == ["1.5×", "12 s", "30 %", "165 µs"]


def test_the_summary_rows_are_read_again_from_the_pages_outputs():
    # the summary table's figures are the ones its rows' patterns read from the page's outputs
    # (both are written by the same run): every row, its figure and its reference, to the letter
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    blocks = re.findall(
        r"^`python benchmarks/(\S+)[^`]*`:.*?\n\n```\n(.*?)\n```", page, re.S | re.M
    )
    outputs = dict(blocks)  # a run of some benchmarks (--only) writes both with those only
    results = [(b, "cmd", outputs[b.script]) for b in report.BENCHES if b.script in outputs]
    assert results
    rows = [r for r in report.summary_table(results, False).splitlines() if r.startswith("| ")]
    table = page.split(report.SUMMARY_BEGIN)[1].split(report.SUMMARY_END)[0]
    assert rows == [r for r in table.splitlines() if r.startswith("| ")]
    assert len(rows) == 1 + sum(len(b.summary("")) for b, *_ in results)  # the header, each row


def test_no_benchmark_puts_its_checkout_before_pythonpath():
    # a run with PYTHONPATH=<other checkout> must measure that checkout (docs/benchmarks.md)
    scripts = sorted((ROOT / "benchmarks").glob("*.py"))
    for root in ("Path(__file__).resolve().parent.parent", "ROOT"):
        assert not [s.name for s in scripts if f"sys.path.insert(0, str({root}))" in s.read_text()]
    appended = [s.name for s in scripts if "sys.path.append(str(" in s.read_text()]
    assert len(appended) == 9 and "grid.py" in appended and "report.py" in appended


def test_the_warm_up_steps_once_with_each_action_and_a_zero_burst_takes_none():
    path = ROOT / "benchmarks" / "_timing.py"
    spec = importlib.util.spec_from_file_location("bench_timing", path)
    timing = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(timing)

    class Counting:
        num_envs = 4

        def __init__(self):
            self.actions = []

        def step(self, action):
            self.actions.append(action)

    env, synced = Counting(), []
    timing.warm_up(env, [1, 2, 3], sync=lambda: synced.append(True))
    assert env.actions == [1, 2, 3] and synced == [True]
    assert timing.burst(env, [4], 0.0) == 0.0 and env.actions == [1, 2, 3]  # no step


FAMILY_RESET_OUTPUT = """machine: x86_64, 2 CPUs
action        cached ms   fresh ms   ratio
bitmask           0.226     26.274  116.1x
sequential        0.533     25.824   48.5x"""

PPO_CLEANRL_OUTPUT = """machine: x86_64, 2 cores, torch 2.13.0+cpu
settings: 1 torch thread(s); B = 256, T = 16, 4 minibatches, 4 epochs, 64x64

sparse/tracking-m6-1000004-v0
                                  wall        CPU  (steps/s)      last mean return
  torch-ppo                      9,421     29,533                        0.079741
  CleanRL-style                  6,265     19,495
  env only                      75,709    244,876
  torch-ppo / CleanRL-style: 1.51x; torch-ppo / env only: 0.12x

covariance/ch2-pv-2-v0
                                  wall        CPU  (steps/s)      last mean return
  torch-ppo                      8,088     24,933                         104.431
  CleanRL-style                  7,500     23,196
  env only                      30,667     91,793
  torch-ppo / CleanRL-style: 1.07x; torch-ppo / env only: 0.27x

sensor-game/m10-strong-defender-v0
                                  wall        CPU  (steps/s)      last mean return
  torch-ppo                      1,587      4,516                        -15.8017
  CleanRL-style                  1,018      3,155
  env only                       2,643      7,870
  torch-ppo / CleanRL-style: 1.43x; torch-ppo / env only: 0.57x"""


def test_the_family_reset_and_cleanrl_benchmarks_are_in_the_report():
    by_name = {b.name: b for b in report.BENCHES}
    reset, ppo = by_name["family_reset"], by_name["ppo_cleanrl"]
    assert (reset.script, ppo.script) == ("family_reset.py", "ppo_cleanrl.py")
    assert all((ROOT / "benchmarks" / b.script).is_file() for b in report.BENCHES)
    assert [r[1:] for r in reset.summary(FAMILY_RESET_OUTPUT)] == [
        ("0.226 ms (116.1× faster)", "every system prepared afresh 26.274 ms"),
        ("0.533 ms (48.5× faster)", "every system prepared afresh 25.824 ms"),
    ]
    assert [r[1:] for r in ppo.summary(PPO_CLEANRL_OUTPUT)] == [
        ("1.51× (29,533 steps/s)", "CleanRL-style 19,495 steps/s"),
        ("1.07× (24,933 steps/s)", "CleanRL-style 23,196 steps/s"),
        ("1.43× (4,516 steps/s)", "CleanRL-style 3,155 steps/s"),
    ]
    # the rows name the tasks the script measures by default
    source = (ROOT / "benchmarks" / "ppo_cleanrl.py").read_text()
    defaults = re.search(r"^TASKS = \((.*?)\)$", source, re.M | re.S)[1]
    assert re.findall(r'"([^"]+)"', defaults) == list(report.PPO_TASKS)
