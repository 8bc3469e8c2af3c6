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
import re
from pathlib import Path

import numpy as np

from fdia_env.registration import ENV_NAMES, get_env, load, view_kwargs

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
    for agent in env.agents:  # the same random step, so the same image, at every build
        env.action_space(agent).seed(0)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    image = env.render()
    _write_png(static / f"{name}.png", image)
    views = get_env(name).views
    ids = list(views.values())
    lines = [f"# `{name}`", "", summary, ""]
    lines += [f"![{name} rendered after one random step](../_static/envs/{name}.png)", ""]
    package, _, leaf = get_env(name).module.rpartition(".")
    lines += ["| | |", "|---|---|", f"| import | `from {package} import {leaf}` |"]
    lines += [f"| agents | {', '.join(f'`{a}`' for a in env.possible_agents)} |"]
    for agent in env.possible_agents:
        lines += [f"| `{agent}` action space | `{env.action_space(agent)}` |"]
        lines += [f"| `{agent}` observation space | {_space_cell(env.observation_space(agent))} |"]
    lines += [f"| Gymnasium ids | {', '.join(f'`{i}`' for i in ids) or '–'} |"]
    for gym_id in ids:
        lines += [
            f"| `{gym_id}` observation space | {_space_cell(_gym_env(gym_id).observation_space)} |"
        ]
    lines += ["", "(Default arguments; the shapes grow with the system's sensors and states.)", ""]
    lines += [_myst_body(body), ""]
    lines += [usage_section(name)]
    return "\n".join(lines) + "\n"


def _gym_env(gym_id: str):
    import gymnasium as gym

    return gym.make(gym_id)


def _space_cell(space) -> str:
    """A space for the header table: shape, dtype and bounds; a Dict key by key."""
    from gymnasium import spaces

    if isinstance(space, spaces.Dict):
        return "`Dict`: " + "; ".join(f"`{k}`: {_space_cell(v)}" for k, v in space.spaces.items())
    if isinstance(space, spaces.Box):
        low, high = np.unique(space.low), np.unique(space.high)
        values = (
            f"[{low[0]:g}, {high[0]:g}]"
            if len(low) == len(high) == 1
            else f"low {space.low.tolist()}, high {space.high.tolist()}"
        )
        return f"`Box` shape `{space.shape}`, `{space.dtype}`, values {values}"
    return f"`{space}`"


def _masked(space) -> bool:
    from gymnasium import spaces

    return isinstance(space, spaces.Dict) and "action_mask" in space.spaces


def usage_section(name: str) -> str:
    """Usage snippets: the AEC and parallel PettingZoo APIs and each Gymnasium view.

    Every snippet is run by the test suite (``tests/test_docs.py``) for every env.
    """
    env = load(name).parallel_env()
    package, _, leaf = get_env(name).module.rpartition(".")
    masked = any(_masked(env.observation_space(a)) for a in env.possible_agents)
    sample = "env.action_space(agent).sample({mask})"
    aec_mask = 'observation["action_mask"]' if masked else ""
    par_mask = 'observations[agent]["action_mask"]' if masked else ""
    out = ["## Usage", "", "### AEC (one agent at a time)", "", "```python"]
    out += [
        f"from {package} import {leaf}",
        "",
        f"env = {leaf}.env()",
        "env.reset(seed=42)",
        "for agent in env.agent_iter():",
        "    observation, reward, termination, truncation, info = env.last()",
        "    if termination or truncation:",
        "        action = None",
        "    else:",
        "        # this is where you would insert your policy",
        f"        action = {sample.format(mask=aec_mask)}",
        "    env.step(action)",
        "env.close()",
        "```",
        "",
        "### Parallel (all agents at once)",
        "",
        "```python",
        f"from {package} import {leaf}",
        "",
        f"env = {leaf}.parallel_env()",
        "observations, infos = env.reset(seed=42)",
        "while env.agents:",
        "    # this is where you would insert your policy",
        "    actions = {",
        f"        agent: {sample.format(mask=par_mask)}",
        "        for agent in env.agents",
        "    }",
        "    observations, rewards, terminations, truncations, infos = env.step(actions)",
        "env.close()",
        "```",
        "",
    ]
    views = get_env(name).views
    if masked:
        out += [
            "A masked agent's PettingZoo observation is a `Dict` of the features (`observation`)",
            "and the legal actions (`action_mask`, 1 = legal).",
            "",
        ]
    if not views:
        out += ["This module has no Gymnasium view: use the PettingZoo APIs above.", ""]
        return "\n".join(out)
    out += ["### Gymnasium view (single agent)", ""]
    out += [
        "Each id below is one agent's view as a Gymnasium env (in a two-player game the other "
        "player is fixed to the module's default opponent; `opponent=` changes it). The "
        "observation is the plain `Box` of features"
        + (
            '; the action mask moves to `info["action_mask"]` and `env.action_masks()` '
            "(what sb3-contrib's MaskablePPO reads; through `gym.make`'s wrappers it is "
            "`env.unwrapped.action_masks()`)."
            if masked
            else "."
        ),
        "",
    ]
    for agent, gym_id in views.items():
        # the view's env: the default one, with the table's fixed options for that view
        view_env = load(name).parallel_env(**view_kwargs(get_env(name).module, agent))
        mask = 'info["action_mask"]' if _masked(view_env.observation_space(agent)) else ""
        out += [
            "```python",
            "import gymnasium as gym",
            "",
            "import fdia_env  # registers the ids",
            "",
            f'env = gym.make("{gym_id}")  # the {agent}',
            "observation, info = env.reset(seed=42)",
            "terminated = truncated = False",
            "while not (terminated or truncated):",
            f"    action = env.action_space.sample({mask})  # your policy here",
            "    observation, reward, terminated, truncated, info = env.step(action)",
            "env.close()",
            "```",
            "",
        ]
    return "\n".join(out)


_ROLE = re.compile(r":(class|func|meth|mod|attr|data|obj|exc):`([^`]+)`")
_MATH_CITATION = re.compile(r"docs/math\.md §([0-9]+(?:\.[0-9]+)?)")


def _myst_body(body: str) -> str:
    """The module docstring as MyST.

    Doctests become code blocks; reST roles (literal text in Markdown) and math citations become
    MyST roles.
    """
    out = []
    for line in _examples_as_code(body).split("\n"):
        if not line.startswith((">>>", "...")):
            line = _ROLE.sub(lambda m: f"{{py:{m.group(1)}}}`{m.group(2)}`", line)
            line = _MATH_CITATION.sub(
                lambda m: f"{{ref}}`math §{m.group(1)} <math-{m.group(1).replace('.', '-')}>`",
                line,
            )
        out.append(line)
    return "\n".join(out)


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
        # a re-export is shown here but indexed only on the page of the package it lives in (or,
        # for a module outside every API package, on the first API page that shows it)
        own = _index_page(obj) == module_name
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


def _index_page(obj) -> str | None:
    """The one API page that indexes ``obj`` (its anchor for links and the source's back-link)."""
    if not callable(obj):  # constants: shown on every page that exports them, indexed on none
        return None
    home = getattr(obj, "__module__", "") or ""
    showing = [package for package, _ in API_PACKAGES if _exports(package, obj)]
    # the most specific page whose package holds the defining module, else the first that shows it
    homes = [p for p in showing if home == p or home.startswith(p + ".")]
    if homes:
        return max(homes, key=len)
    return showing[0] if showing else None


def _exports(package: str, obj) -> bool:
    module = importlib.import_module(package)
    return any(getattr(module, name, None) is obj for name in public_names(module))


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
