"""``python -m course site``: the static website builds offline from the saved notebooks, with a page per lecture
showing every figure its notebook saved, and no link inside the site leading nowhere. (The browser walk of the
built site is in tests/test_browser.py, opt-in.)"""
import json
from pathlib import Path

import pytest

from course import site

ROOT = Path(__file__).resolve().parents[1]
# MyST-Parser's use of an API Sphinx 11 removes: theirs to fix, nothing the site does
pytestmark = pytest.mark.filterwarnings("ignore:.*is deprecated. Check CHANGES for Sphinx API modifications")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    pytest.importorskip("sphinx", reason='the site needs Sphinx: pip install -e ".[site]"')
    pytest.importorskip("myst_nb", reason='the site needs MyST-NB: pip install -e ".[site]"')
    return site.build_site(tmp_path_factory.mktemp("site") / "site")


def _figures(notebook: Path) -> int:
    """How many figures a notebook's saved outputs hold (PNG outputs)."""
    nb = json.loads(notebook.read_text(encoding="utf-8"))
    return sum("image/png" in out.get("data", {}) for cell in nb["cells"] for out in cell.get("outputs", []))


def test_every_lecture_has_a_page_with_every_saved_figure(built):
    root = built.parent
    assert built.is_file() and (root / "README.html").is_file() and (root / "docs" / "syllabus.html").is_file()
    notebooks = sorted((ROOT / "lectures").glob("[0-9][0-9]_*.ipynb"))
    assert len(notebooks) >= 14 and len(notebooks) == len(list((ROOT / "solutions").glob("[0-9][0-9]_*.ipynb")))
    for notebook in notebooks:
        page = root / "lectures" / f"{notebook.stem}.html"
        assert page.is_file(), page
        text = page.read_text(encoding="utf-8")
        assert text.count("<img") >= _figures(notebook), f"{page.name}: figures missing"
        assert "# 0" not in text[:200]                                 # a heading, not raw markdown
    index = built.read_text(encoding="utf-8")
    assert all(f"lectures/{n.stem}.html" in index for n in notebooks)


def test_no_link_inside_the_site_is_broken(built):
    assert site.check_links(built.parent) == []


def test_check_links_finds_a_broken_link(tmp_path):
    (tmp_path / "a.html").write_text('<a href="b.html">b</a> <img src="_images/x.png"> <a href="https://x.org">x</a>'
                                     ' <a href="#top">top</a>')
    (tmp_path / "b.html").write_text("<p>b</p>")
    assert site.check_links(tmp_path) == ["a.html: _images/x.png"]


def test_the_site_is_never_built_over_the_course(tmp_path):
    with pytest.raises((ValueError, RuntimeError)):
        site.build_site(ROOT)
