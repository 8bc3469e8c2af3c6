"""The leaderboard: JSON rows and each task's stored references as Markdown and plots.

For every task: random play, each heuristic and the certified reference from the task's stored
references (:attr:`fdia_env.tasks.Task.references`, normalised with ``task.normalise``), then
each learner of the rows: the mean of its seeds' normalised scores with the 95 % Student-t
interval over the seeds, its raw mean return, and the budget it trained with; seeds whose run
failed are named with their error (a learner whose every seed failed shows "failed"). One bar
plot per task family (normalised score per method, with the intervals) goes to the figures
folder, which the page links relative to itself.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

START, END = "<!-- leaderboard:start -->", "<!-- leaderboard:end -->"
FLOOR = -1.5  # the plots' lowest normalised score; a bar below it is cut and its value written


def seed_interval(values: Iterable[float]) -> tuple[float, float]:
    """Mean and 95 % Student-t half-width over seeds (NaN half-width for one seed)."""
    from agents.evaluate import t_interval

    arr = np.asarray([v for v in values if v is not None], dtype=np.float64)
    if arr.size == 0:
        return math.nan, math.nan
    return float(arr.mean()), t_interval(arr)


def reference_entries(task: Any) -> list[dict[str, Any]]:
    """The task's stored references as leaderboard entries (method, normalised, raw, note)."""
    from agents.bench.score import reference_rows

    return [
        {"method": name, "normalised": float(task.normalise(raw)), "ci95": None, "raw": raw,
         "note": note}
        for name, raw, note in reference_rows(task)
    ]  # fmt: skip


def _error(row: dict[str, Any]) -> str:
    """A failed row's error on one line of a Markdown table (at most 160 characters)."""
    text = " ".join(str(row.get("error", "unknown error")).split()).replace("|", "\\|")
    return text if len(text) <= 160 else text[:159] + "…"


def learner_entries(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One entry per learner (method) of one task's rows: the seeds' mean ± 95 % CI.

    Failed runs (:func:`agents.leaderboard.rows.failed`) count in no mean; the note names their
    seeds and errors, and a learner with no other run gets NaN scores and ``failed`` True.
    """
    from agents.leaderboard.rows import failed

    by_method: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        by_method[row["method"]].append(row)
    out = []
    for method, group in by_method.items():
        group = sorted(group, key=lambda r: r["seed"])
        done = [r for r in group if not failed(r)]
        broken = [r for r in group if failed(r)]
        mean, half = seed_interval(r["normalised"] for r in done)
        raw_values = [r.get("raw", r.get("mean")) for r in done]
        raw = float(np.mean(raw_values)) if done and None not in raw_values else math.nan
        notes = []
        if done:
            steps = sorted({r["timesteps"] for r in done})
            notes.append(
                f"{len(done)} seed{'s' * (len(done) != 1)}, "
                f"{', '.join(f'{s:,}' for s in steps)} steps, "
                f"{np.mean([r['train_seconds'] for r in done]):.0f} s per seed"
            )
        notes += [f"seed {r['seed']} failed: {_error(r)}" for r in broken]
        out.append(
            {
                "method": method,
                "normalised": mean,
                "ci95": half,
                "raw": raw,
                "note": "; ".join(notes),
                "per_seed": [r["normalised"] for r in done],
                "failed": not done,
            }
        )
    return out


def _num(v: float | None, fmt: str = ".3f") -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)


def task_table(task: Any, rows: list[dict[str, Any]]) -> str:
    """The Markdown table of one task."""
    unit = "worst-case return" if task.is_game else "return"
    lines = [
        f"**{task.name}** ({task.family}, {task.player}, {task.difficulty})",
        "",
        f"| method | normalised score | raw ({unit}) | notes |",
        "|---|---|---|---|",
    ]
    for entry in reference_entries(task) + learner_entries(rows):
        norm = "failed" if entry.get("failed") else _num(entry["normalised"])
        if entry["ci95"] is not None and math.isfinite(entry["ci95"]):
            norm += f" ± {entry['ci95']:.3f}"
        lines.append(
            f"| {entry['method']} | {norm} | {_num(entry['raw'], '.6g')} | {entry['note']} |"
        )
    return "\n".join(lines)


def family_plot(path: Path, family: str, tasks: list[Any], rows: dict[str, list]) -> Path:
    """Bar plot of the normalised score per method on each task of ``family`` (95 % CIs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.plots import save_figure

    per_task = {t.name: reference_entries(t) + learner_entries(rows.get(t.name, [])) for t in tasks}
    optimum_names = {t.references.optimum.name for t in tasks}

    def label(method: str) -> str:  # one colour for the certified reference of every task
        return "certified reference" if method in optimum_names else method

    methods: list[str] = []
    for entries in per_task.values():
        for e in entries:
            if label(e["method"]) not in methods:
                methods.append(label(e["method"]))
    colours = {m: f"C{j % 10}" for j, m in enumerate(methods)}
    widest = max(len(entries) for entries in per_task.values())
    width = 0.8 / max(1, widest)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(tasks) + 2) + 3.0, 3.8))
    shown: set[str] = set()
    for i, t in enumerate(tasks):
        entries = per_task[t.name]
        for k, e in enumerate(entries):
            if not math.isfinite(e["normalised"]):  # a learner whose every run failed
                continue
            name = label(e["method"])
            ci = e["ci95"]
            ax.bar(
                i + (k - (len(entries) - 1) / 2) * width,
                e["normalised"],
                width,
                yerr=0.0 if ci is None or not math.isfinite(ci) else ci,
                capsize=2,
                color=colours[name],
                label=None if name in shown else name,
            )
            shown.add(name)
            if e["normalised"] < FLOOR:  # far below random play: the bar is cut, its value written
                x = i + (k - (len(entries) - 1) / 2) * width
                ax.text(x, FLOOR, f"{e['normalised']:.1f}", fontsize=6, ha="center", va="bottom")
    low = min(
        (e["normalised"] for v in per_task.values() for e in v if math.isfinite(e["normalised"])),
        default=0.0,
    )
    ax.set_ylim(max(FLOOR, min(-0.1, low - 0.1)), 1.15)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.axhline(1.0, color="k", lw=0.6, ls="--")
    ax.set_xticks(range(len(tasks)))
    ax.set_xticklabels([t.name.split("/", 1)[-1] for t in tasks], rotation=20, ha="right")
    ax.set_ylabel("normalised score")
    ax.set_title(f"{family}: 0 = random play, 1 = the certified reference")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return save_figure(fig, path, dpi=110)


def leaderboard(
    tasks: list[Any],
    rows: list[dict[str, Any]],
    figures: Path | None,
    header: str,
    figures_link: str = "figures",
) -> str:
    """The leaderboard section: ``header``, one table per task, one figure per family.

    Args:
        tasks: The tasks, in the page's order.
        rows: The learners' rows (of these tasks and others).
        figures: The folder the family plots are written to (None: no plots).
        header: The section's first paragraph.
        figures_link: The figures folder as the page links it (relative to the page).
    """
    by_task: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        by_task[row["task"]].append(row)
    families: dict[str, list[Any]] = defaultdict(list)
    for t in tasks:
        families[t.family].append(t)
    parts = [header]
    for family, group in families.items():
        parts.append(f"### {family}")
        if figures is not None:
            name = f"benchmark_{re.sub(r'[^a-z0-9]+', '_', family.lower())}.png"
            family_plot(figures / name, family, group, by_task)
            parts.append(f"![normalised scores on the {family} tasks]({figures_link}/{name})")
        parts.extend(task_table(t, by_task.get(t.name, [])) for t in group)
    return "\n\n".join(parts)


def write_section(page: Path, section: str, title: str = "Leaderboard") -> None:
    """Replace the text between the leaderboard markers of ``page`` with ``section``.

    A page that does not exist is created: ``# title`` and the markers around ``section``. The
    page is replaced atomically.

    Raises:
        ValueError: When an existing page lacks the markers (naming the page).
    """
    from agents.runs import atomic_write

    page = Path(page)
    text = page.read_text(encoding="utf-8") if page.exists() else f"# {title}\n\n{START}\n{END}\n"
    if START not in text or END not in text:
        raise ValueError(f"page {page} has no {START} … {END} markers for the leaderboard")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    new = f"{head}{START}\n\n{section}\n\n{END}{tail}"
    atomic_write(page, lambda fh: fh.write(new.encode("utf-8")))
