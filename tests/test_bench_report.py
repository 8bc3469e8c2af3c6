"""benchmarks/report.py: the generated section of the benchmarks page is replaced, not appended."""

import importlib.util
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
