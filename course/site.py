"""``python -m course site [--out site]``: the course as a static website, built offline from the saved notebooks.

The pages: the README (the start page), the syllabus (``docs/syllabus.md``), the thirteen lectures with their
saved outputs and figures (never re-run: the site shows exactly what nbval checks), the licences and the
changelog. Built with Sphinx and MyST-NB (``pip install -e ".[site]"``): Sphinx because it is the maintained
documentation tool of the Python world that builds offline (Jupyter Book 2 builds with a Node.js tool that fetches
its theme at build time, which this course's machines cannot), MyST-NB because it renders notebooks with their
saved outputs and reads the README's Markdown as it is. The theme is Sphinx's own (alabaster): nothing to install
beyond the two packages, nothing fetched at build time. Open ``site/index.html`` in a browser.

The sources are copied into a temporary folder first (the repository is never written to) with a generated
``conf.py`` and ``index.md``; Sphinx's warnings are printed, and links inside the site that lead nowhere are
reported by ``check_links`` (``--check``, also run by the tests).
"""
from __future__ import annotations

import argparse
import html.parser
import shutil
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote, urlsplit

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "docs/syllabus.md", "LICENSE-CONTENT.md", "CHANGELOG.md")

CONF = '''\
project = "Differentiable rendering, from scratch"
author = "the authors of the differentiable rendering course"
copyright = "2026, " + author
extensions = ["myst_nb"]
nb_execution_mode = "off"                  # the saved outputs, as nbval checks them
# an explorer's output is a widget (no state is saved, so nothing to draw) and its defaults' still picture: show that
nb_mime_priority_overrides = [("html", "application/vnd.jupyter.widget-view+json", None)]
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header", "myst.xref_missing", "misc.highlighting_failure", "toc.not_included"]
exclude_patterns = ["_build"]
html_theme = "alabaster"
html_theme_options = {"page_width": "1200px", "sidebar_width": "260px"}
html_title = project
'''

__all__ = ["build_site", "check_links", "cli"]


def _sources(folder: Path) -> list[str]:
    """Copy the pages, the lecture notebooks and the images they show into ``folder``; returns the lecture
    documents' names (``lectures/01_...``)."""
    for page in PAGES:
        target = folder / page
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / page, target)
    (folder / "LICENSE.md").write_text("# LICENSE (code)\n\n```text\n" + (ROOT / "LICENSE").read_text() + "```\n")
    for image in (ROOT / "docs").glob("*.png"):
        shutil.copyfile(image, folder / "docs" / image.name)
    (folder / "lectures").mkdir()
    lectures = []
    for notebook in sorted((ROOT / "lectures").glob("[0-9][0-9]_*.ipynb")):
        shutil.copyfile(notebook, folder / "lectures" / notebook.name)
        lectures.append(f"lectures/{notebook.stem}")
    return lectures


def _index(lectures: list[str]) -> str:
    return ("# Differentiable rendering, from scratch\n\n"
            "A course on rendering and differentiable rendering around a renderer you can read end to end. "
            "Start with the [README](README.md): it sets the course up in one command.\n\n"
            "```{toctree}\n:maxdepth: 1\n:caption: The course\n\nREADME\ndocs/syllabus\n```\n\n"
            "```{toctree}\n:maxdepth: 1\n:caption: Lectures\n\n" + "\n".join(lectures) + "\n```\n\n"
            "```{toctree}\n:maxdepth: 1\n:caption: About\n\nLICENSE-CONTENT\nLICENSE\nCHANGELOG\n```\n")


def build_site(out, *, quiet: bool = True) -> Path:
    """Build the site into ``out`` (a folder, replaced); returns the path of its ``index.html``."""
    try:
        from sphinx.cmd.build import build_main
    except ImportError as error:                                      # an optional extra
        raise RuntimeError('the site needs Sphinx and MyST-NB: pip install -e ".[site]"') from error
    out = Path(out).resolve()
    if out == ROOT or ROOT in out.parents and out.name in ("lectures", "course", "docs"):
        raise ValueError(f"refusing to build the site into {out}")
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "source"
        source.mkdir()
        lectures = _sources(source)
        (source / "conf.py").write_text(CONF)
        (source / "index.md").write_text(_index(lectures))
        if out.exists():
            shutil.rmtree(out)
        code = build_main(["-b", "html", "-j", "1", *(["-q"] if quiet else []), str(source), str(out),
                           "-d", str(Path(tmp) / "doctrees")])
    if code != 0:
        raise RuntimeError(f"sphinx-build failed (exit code {code})")
    return out / "index.html"


class _Links(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.links = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("href", "src"):
            if tag in ("a", "img", "link", "script") and attrs.get(key):
                self.links.append((tag, attrs[key]))


def check_links(site) -> list[str]:
    """Every ``href`` and ``src`` of the site's pages that points inside the site but to no file: one line per
    broken link ("page: link"); empty when none is broken. External links (with a scheme) are not followed."""
    site = Path(site)
    broken = []
    for page in sorted(site.rglob("*.html")):
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8", errors="replace"))
        for tag, link in parser.links:
            parts = urlsplit(link)
            if parts.scheme or link.startswith(("#", "//", "mailto:")) or not parts.path:
                continue
            target = (page.parent / unquote(parts.path)).resolve()
            if not target.exists():
                broken.append(f"{page.relative_to(site)}: {link}")
    return broken


def cli(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m course site", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="site", help="the folder to build into (default: site/, git-ignored)")
    parser.add_argument("--verbose", action="store_true", help="Sphinx's own progress lines")
    args = parser.parse_args(argv)
    try:
        index = build_site(args.out, quiet=not args.verbose)
    except (RuntimeError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    broken = check_links(index.parent)
    for line in broken:
        print(f"broken link: {line}", file=sys.stderr)
    print(f"site written to {index} ({len(list(index.parent.rglob('*.html')))} pages); open it in a browser")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(cli())
