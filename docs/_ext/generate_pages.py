"""Build-time pages: the environments and the API reference.

One page per environment module (from its docstring, with a rendered image) and one per public
package of the API (from its ``__all__``).

The env modules' docstrings follow Gymnasium's sections in Markdown, so the pages are those
docstrings, not a second copy: the title comes from the first line, the ``>>>`` example becomes
a code block, and the Gymnasium ids registered for the module are listed from its entry in
the table of environments, ``fdia_env.registration.ENVS``.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

import numpy as np

from fdia_env.registration import ENV_NAMES, get_env, load

ENV_MODULES = list(ENV_NAMES)  # one page per entry of the table of environments
API_PACKAGES = [
    ("fdia_env", "Top-level package: systems, episode spec, registration"),
    ("fdia_env.systems", "Linear systems, sensors, the tracking model, validation"),
    ("fdia_env.kalman", "The batched Kalman core"),
    ("fdia_env.backend", "Array backends: numpy, or torch on one device"),
    ("fdia_env.attacks", "Attack models"),
    ("fdia_env.defenses", "Defense models"),
    ("fdia_env.envs", "The simulation engine, the PettingZoo env and its Gymnasium view"),
    ("fdia_env.vector", "Native vector environments"),
    ("fdia_env.wrappers", "Wrappers for client libraries"),
    ("fdia_env.stealth", "Static state estimation under bad-data detection"),
    ("baselines.sparse", "Sparse attacks: EXS, SFS, SBS, SFS-SS, DP"),
    ("baselines.covariance", "Attack covariances: trace and determinant optima"),
    ("baselines.game", "The sensor-selection game: LP, Bayesian, double oracle"),
    ("baselines.detection", "Detectors: OBDD, OBDI, CBD, CSD, MMSE"),
    ("baselines.stealth", "Stealthy attacks: security index, budgeted attacks, protection"),
    ("agents.evaluate", "Scoring policies against the analytic references"),
    ("agents.registry", "What can be trained, with its reference"),
    ("agents.training", "stable-baselines3 training"),
    ("agents.selfplay", "Iterated best response, fictitious self-play, PSRO"),
    ("agents.checkpoint", "Checkpoints that cannot run code"),
]


def public_names(module) -> list[str]:
    """``__all__``, else the functions and classes defined in the module itself."""
    names = getattr(module, "__all__", None)
    if names is not None:
        return list(names)
    return [
        n
        for n, v in vars(module).items()
        if not n.startswith("_")
        and (inspect.isfunction(v) or inspect.isclass(v))
        and getattr(v, "__module__", None) == module.__name__
    ]


def env_page(name: str, static: Path) -> str:
    """Markdown of the env module's page; writes its render image into ``static``."""
    module = load(name)
    doc = inspect.getdoc(module) or ""
    first, _, body = doc.partition("\n")
    summary = first.split(":", 1)[1].strip() if ":" in first else first
    env = module.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    image = env.render()
    _write_png(static / f"{name}.png", image)
    ids = list(get_env(name).views.values())
    lines = [f"# `{name}`", "", summary, ""]
    lines += [f"![{name} rendered after one random step](../_static/envs/{name}.png)", ""]
    package, _, leaf = get_env(name).module.rpartition(".")
    lines += ["| | |", "|---|---|", f"| import | `from {package} import {leaf}` |"]
    lines += [f"| agents | {', '.join(f'`{a}`' for a in env.possible_agents)} |"]
    for agent in env.possible_agents:
        lines += [f"| `{agent}` action space | `{env.action_space(agent)}` |"]
    lines += [f"| Gymnasium ids | {', '.join(f'`{i}`' for i in ids) or '–'} |", ""]
    lines += [_examples_as_code(body)]
    return "\n".join(lines) + "\n"


def _examples_as_code(body: str) -> str:
    """Doctest lines (``>>>``, ``...`` and their output) as fenced python blocks."""
    out, in_block = [], False
    for line in body.splitlines():
        is_doctest = line.startswith((">>>", "..."))
        if is_doctest and not in_block:
            out.append("```python")
            in_block = True
        elif in_block and not line.strip():
            out.append("```")
            in_block = False
        out.append(line)
    if in_block:
        out.append("```")
    return "\n".join(out)


def api_page(module_name: str, title: str) -> str:
    """MyST page with autodoc directives for every public name of ``module_name``."""
    module = importlib.import_module(module_name)
    lines = [f"# `{module_name}`", "", title + ".", "", "```{eval-rst}"]
    lines += [f".. module:: {module_name}", ""]
    for name in public_names(module):
        obj = getattr(module, name)
        target = f"{module_name}.{name}"
        home = getattr(obj, "__module__", "") or ""
        # a re-export is shown here but indexed only on the page of the package it lives in
        own = _home_page(home) == module_name
        extra = [] if own else ["   :no-index:"]
        if inspect.isclass(obj):
            lines += [f".. autoclass:: {target}", "   :members:", *extra, ""]
        elif callable(obj):
            lines += [f".. autofunction:: {target}", *extra, ""]
        elif inspect.ismodule(obj):
            continue
        else:  # a constant: its value's type, not the type's docstring
            size = f" with {len(obj)} entries" if hasattr(obj, "__len__") else ""
            lines += [
                f".. py:data:: {target}",
                *extra,
                "",
                f"   A `{type(obj).__name__}`{size}.",
                "",
            ]
    lines += ["```", ""]
    return "\n".join(lines)


def _home_page(home: str) -> str | None:
    """The most specific API page whose package contains the module ``home``."""
    pages = [m for m, _ in API_PACKAGES if home == m or home.startswith(m + ".")]
    return max(pages, key=len) if pages else None


def _write_png(path: Path, image: np.ndarray) -> None:
    from matplotlib.image import imsave

    path.parent.mkdir(parents=True, exist_ok=True)
    imsave(path, np.ascontiguousarray(image))


def _write_if_changed(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def generate(app) -> None:
    """Write the generated pages before Sphinx reads the sources."""
    src = Path(app.srcdir)
    static = src / "_static" / "envs"
    for name in ENV_MODULES:
        _write_if_changed(src / "environments" / f"{name}.md", env_page(name, static))
    for module_name, title in API_PACKAGES:
        _write_if_changed(src / "api" / f"{module_name}.md", api_page(module_name, title))


def setup(app):
    """Sphinx extension entry point."""
    app.connect("builder-inited", generate)
    return {"parallel_read_safe": True, "version": "1"}
