"""Internal links of the built site: viewcode's "[docs]" back-links fixed, every anchor checked.

Three build steps:

- :func:`link_citations` turns a docstring's "docs/math.md §4" into a link to that section.
- ``sphinx.ext.viewcode`` links each highlighted source block back to the object's
  documentation, but it takes the page from the *last* document that showed the object and the
  anchor prefix from the *first*. An object re-exported by a second API page (documented there
  with ``:no-index:``, so without an anchor) then gets a back-link to an anchor that does not
  exist. :func:`fix_viewcode_backlinks` points every back-link at the page and anchor where the
  Python domain indexed the object.
- After an HTML build, :func:`check_local_links` reads every page and reports each link to a
  missing file or to a missing ``#anchor`` within the site as a Sphinx warning, so that
  ``make docs`` (warnings are errors) fails on it.
"""

from __future__ import annotations

import html
import importlib
import re
import shutil
import urllib.parse
from collections import Counter
from pathlib import Path

from sphinx.util import logging

logger = logging.getLogger(__name__)

_HREF = re.compile(r'\bhref="([^"]*)"')
_ID = re.compile(r'\bid="([^"]+)"')


def _defined_in(qualified: str) -> str | None:
    """The module that defines the object named ``pkg.mod.Name[.attr]``, or None."""
    parts = qualified.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return getattr(obj, "__module__", None)
    return None


def fix_viewcode_backlinks(app, env) -> None:
    """Point viewcode's back-links at the indexed documentation of each object."""
    modules = getattr(env, "_viewcode_modules", None)
    if not modules:
        return
    objects = env.get_domain("py").objects
    for modname, entry in list(modules.items()):
        if not entry:
            continue
        code, tags, used, refname = entry
        found: dict[str, tuple[str, str]] = {}  # fullname -> (prefix, docname)
        for fullname in used:
            for name, obj in objects.items():
                if obj.aliased or not name.endswith("." + fullname):
                    continue
                prefix = name[: -len(fullname) - 1]
                top = f"{prefix}.{fullname.split('.')[0]}"
                if _defined_in(top) == modname:
                    found[fullname] = (prefix, obj.docname)
                    break
        if not found:  # shown only without an index entry: no back-link rather than a broken one
            modules[modname] = (code, tags, {}, refname)
            continue
        prefix = Counter(p for p, _ in found.values()).most_common(1)[0][0]
        fixed = {fullname: docname for fullname, (p, docname) in found.items() if p == prefix}
        modules[modname] = (code, tags, fixed, prefix)


def check_local_links(app, exception) -> None:
    """Warn about every link to a missing page or anchor of the built HTML site."""
    if exception is not None or app.builder.format != "html":
        return
    out = Path(app.outdir)
    ids: dict[Path, set[str] | None] = {}

    def anchors(page: Path) -> set[str] | None:
        if page not in ids:
            ids[page] = (
                set(_ID.findall(page.read_text(encoding="utf-8"))) if page.exists() else None
            )
        return ids[page]

    for page in sorted(out.rglob("*.html")):
        text = page.read_text(encoding="utf-8")
        for raw in _HREF.findall(text):
            href = html.unescape(raw)
            if not href or re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", href):
                continue  # external (https:, mailto:, ...)
            path, _, fragment = href.partition("#")
            path = urllib.parse.unquote(path.partition("?")[0])
            target = (page.parent / path).resolve() if path else page.resolve()
            where = page.relative_to(out)
            if path and not target.exists():
                logger.warning(f"broken link in {where}: {href} (no such file)")
                continue
            if fragment and target.suffix == ".html":
                found = anchors(target)
                if found is not None and urllib.parse.unquote(fragment) not in found:
                    logger.warning(f"broken link in {where}: {href} (no such anchor)")


_CITATION = re.compile(r"docs/(math|references)\.md §([0-9]+(?:\.[0-9]+)?)")


def link_citations(app, what, name, obj, options, lines: list[str]) -> None:
    """Make "docs/math.md §2.2" in a docstring a link to that section of the site's page.

    Doctest lines and inline literals (an odd number of double backquotes before the citation)
    are left as they are.
    """
    for i, line in enumerate(lines):
        if not line.lstrip().startswith((">>>", "...")):
            lines[i] = _CITATION.sub(lambda m, text=line: _citation_link(m, text), line)


def _citation_link(match: re.Match, line: str) -> str:
    if line[: match.start()].count("``") % 2:  # inside an inline literal
        return match.group(0)
    page, section = match.groups()
    return f":ref:`docs/{page}.md §{section} <{page}-{section.replace('.', '-')}>`"


def fresh_source_pages(app) -> None:
    """Remove last build's highlighted sources, so that viewcode writes them with today's links.

    viewcode skips a source page that is newer than its module, which would keep a back-link of
    an earlier build (and fail the link check) after only the documentation changed.
    """
    if app.builder.format == "html":
        shutil.rmtree(Path(app.outdir) / "_modules", ignore_errors=True)


def setup(app):
    """Sphinx extension entry point."""
    # after every document is read, before viewcode writes its source pages
    app.connect("env-updated", fix_viewcode_backlinks)
    app.connect("builder-inited", fresh_source_pages)
    app.connect("build-finished", check_local_links)
    app.connect("autodoc-process-docstring", link_citations)
    return {"parallel_read_safe": True, "version": "1"}
