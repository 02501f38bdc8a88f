"""The explorers in a real browser (opt in: ``pytest -m browser tests/test_browser.py`` or ``COURSE_BROWSER=1``).

JupyterLab is started on a free port with a token, in a temporary folder holding a notebook whose cells are
the explorers of lectures 03 and 05 (float sliders that redraw live; an integer slider, a checkbox and a
drop-down that redraw on release). Chromium (``/usr/bin/chromium``, driven by Playwright) opens it, runs all
cells, then moves one control of each kind and checks that the explorer's picture changed (the ``src`` of its
image). Screenshots of the notebook at 1024 and 1400 px wide, before and after, are kept in
``browser-artefacts/`` at the top of the repository (``COURSE_BROWSER_ARTEFACTS`` names another folder).

Skipped, with the reason, where Playwright or Chromium is missing. Install with ``pip install playwright``
(no ``playwright install``: the system's Chromium is used).
"""
import contextlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

pytestmark = pytest.mark.browser

CHROMIUM = "/usr/bin/chromium"
ROOT = Path(__file__).resolve().parents[1]
CELLS = ["from course import viz", "viz.fill_rule_explorer()", "viz.supersampling_explorer()"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _notebook(path: Path) -> None:
    cells = [dict(cell_type="code", execution_count=None, metadata={}, outputs=[], source=src) for src in CELLS]
    nb = dict(cells=cells, nbformat=4, nbformat_minor=5,
              metadata={"kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python",
                                       "name": "python3"}})
    path.write_text(json.dumps(nb), encoding="utf-8")


@contextlib.contextmanager
def _jupyterlab(root: Path, env: dict, *extra: str):
    """JupyterLab over ``root`` on a free port with a token, up within a minute; yields (url, token), then stops it."""
    port, token = _free_port(), "course-browser-test"
    server = subprocess.Popen([sys.executable, "-m", "jupyter", "lab", "--no-browser", "--allow-root",
                               f"--port={port}", f"--ServerApp.token={token}", "--ServerApp.ip=127.0.0.1",
                               f"--ServerApp.root_dir={root}", "--LabApp.news_url=", "--ServerApp.open_browser=False",
                               *extra], cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(120):                                                # up to a minute to start
            try:
                urllib.request.urlopen(f"{url}/api/status?token={token}", timeout=1)
                break
            except OSError:
                time.sleep(0.5)
        else:
            pytest.fail("JupyterLab did not start within a minute")
        yield url, token
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()


@pytest.fixture
def lab(tmp_path):
    pytest.importorskip("playwright.sync_api", reason="Playwright is missing: pip install playwright")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"Chromium is missing at {CHROMIUM} (apt-get install chromium)")
    _notebook(tmp_path / "explorers.ipynb")
    env = dict(os.environ, MPLBACKEND="module://matplotlib_inline.backend_inline")
    with _jupyterlab(tmp_path, env) as (url, token):
        yield f"{url}/lab/tree/explorers.ipynb?token={token}"


@pytest.fixture
def artefacts():
    folder = Path(os.environ.get("COURSE_BROWSER_ARTEFACTS", ROOT / "browser-artefacts"))
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    return folder


def _picture(cell) -> str:
    """The src of the image inside an explorer's output (its picture)."""
    img = cell.locator(".widget-output img, .jupyter-widgets-output-area img").first
    img.wait_for(timeout=90_000)
    return img.get_attribute("src")


def _shot(page, cell, path) -> None:
    """A screenshot of one cell, scrolled into view and its picture drawn (JupyterLab skips painting cells
    out of view)."""
    cell.scroll_into_view_if_needed()
    _picture(cell)
    page.wait_for_timeout(700)
    cell.screenshot(path=str(path))


def _changed(cell, before: str, what: str, timeout: float = 60.0) -> str:
    deadline = time.time() + timeout
    while time.time() < deadline:
        now = _picture(cell)
        if now != before:
            return now
        time.sleep(0.25)
    pytest.fail(f"the picture did not change after moving {what}")


def test_explorers_redraw_in_jupyterlab(lab, artefacts):
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            _drive(page, lab, artefacts)
        except Exception:
            page.screenshot(path=str(artefacts / "failure.png"), full_page=True)   # what the page showed
            raise
        finally:
            browser.close()


def _drive(page, lab, artefacts):
    """Run the notebook, screenshot it at both widths, move one control of each kind, screenshot again."""
    page.goto(lab, timeout=120_000)
    page.locator(".jp-Notebook").wait_for(timeout=120_000)
    page.locator(".jp-StatusBar-TextItem", has_text="Idle").first.wait_for(timeout=120_000)   # a kernel, idle
    cells = page.locator(".jp-CodeCell")
    cells.first.locator(".jp-InputArea-editor").click()                 # run the cells one by one
    for k in range(len(CELLS)):
        page.keyboard.press("Shift+Enter")
        page.wait_for_timeout(300)
    cells.nth(0).locator(".jp-InputPrompt", has_text="[1]").wait_for(timeout=120_000)
    news = page.locator(".jp-Notification-Toast-Close, .Toastify__close-button").first   # "Jupyter news?"
    if news.count():
        news.click()
    fill, aa = cells.nth(1), cells.nth(2)
    pictures = {"fill": _picture(fill), "aa": _picture(aa)}
    for width in (1024, 1400):
        page.set_viewport_size({"width": width, "height": 1000})
        page.wait_for_timeout(500)
        page.screenshot(path=str(artefacts / f"notebook-{width}px.png"), full_page=True)
        _shot(page, fill, artefacts / f"fill-rule-{width}px.png")
        _shot(page, aa, artefacts / f"supersampling-{width}px.png")

    handle = fill.locator(".widget-slider .noUi-handle").first          # a float slider (x), live
    handle.focus()
    for _ in range(2):
        page.keyboard.press("ArrowLeft")
    pictures["fill"] = _changed(fill, pictures["fill"], "a float slider")

    k = aa.locator(".widget-slider .noUi-handle").first                 # an integer slider (k), on release
    k.focus()
    page.keyboard.press("ArrowRight")
    pictures["aa"] = _changed(aa, pictures["aa"], "an integer slider")
    aa.locator(".widget-checkbox input[type='checkbox']").first.check()  # a checkbox (jitter)
    pictures["aa"] = _changed(aa, pictures["aa"], "a checkbox")
    aa.locator(".widget-dropdown select").first.select_option("teapot")  # a drop-down (shape)
    pictures["aa"] = _changed(aa, pictures["aa"], "a drop-down")
    for width in (1024, 1400):
        page.set_viewport_size({"width": width, "height": 1000})
        page.wait_for_timeout(500)
        _shot(page, fill, artefacts / f"fill-rule-moved-{width}px.png")
        _shot(page, aa, artefacts / f"supersampling-moved-{width}px.png")
    sliders = fill.locator(".widget-slider")                            # usable width at 1024 px
    assert sliders.count() == 3
    assert all(sliders.nth(i).bounding_box()["width"] >= 300 for i in range(3))


# ---- python -m course lab: running a shipped notebook leaves git clean ----------------------------------------

SMALL = ["import time", "print('first')", "time.sleep(3)\nprint('after a pause')"]


@pytest.fixture
def course_lab(tmp_path):
    """JupyterLab as ``python -m course lab`` starts it (the course's server config first on JUPYTER_CONFIG_PATH),
    over a git repository holding lectures/01_small.ipynb and work/own.ipynb, with autosave every second."""
    pytest.importorskip("playwright.sync_api", reason="Playwright is missing: pip install playwright")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"Chromium is missing at {CHROMIUM} (apt-get install chromium)")
    if shutil.which("git") is None:
        pytest.skip("git is missing")
    from course import lab as course_lab_module
    repo = tmp_path / "repo"
    for folder in ("lectures", "work"):
        (repo / folder).mkdir(parents=True)
    cells = [dict(cell_type="code", execution_count=None, metadata={}, outputs=[], source=src) for src in SMALL]
    nb = dict(cells=cells, nbformat=4, nbformat_minor=5,
              metadata={"kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python",
                                       "name": "python3"}})
    for path in (repo / "lectures" / "01_small.ipynb", repo / "work" / "own.ipynb"):
        path.write_text(json.dumps(nb, indent=1), encoding="utf-8")
    (repo / ".gitignore").write_text("/work/\n.ipynb_checkpoints/\n")
    git = dict(cwd=repo, check=True, capture_output=True)
    subprocess.run(["git", "init", "-q"], **git)
    subprocess.run(["git", "add", "-A"], **git)
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "shipped"], **git)
    settings = tmp_path / "settings" / "@jupyterlab" / "docmanager-extension"
    settings.mkdir(parents=True)
    (settings / "plugin.jupyterlab-settings").write_text(json.dumps({"autosave": True, "autosaveInterval": 1}))
    env = course_lab_module.lab_environment()
    env["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    with _jupyterlab(repo, env, f"--LabApp.user_settings_dir={tmp_path / 'settings'}") as (url, token):
        yield repo, url, token


def _run_all(page, url):
    page.goto(url, timeout=120_000)
    page.locator(".jp-NotebookPanel:visible .jp-Notebook").first.wait_for(timeout=120_000)
    page.locator(".jp-StatusBar-TextItem", has_text="Idle").first.wait_for(timeout=120_000)
    news = page.locator(".jp-Notification-Toast-Close, .Toastify__close-button").first   # "Jupyter news?"
    if news.count():
        news.click()
    page.locator(".jp-NotebookPanel:visible .jp-Notebook").first.click()  # this notebook has the focus
    page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()  # Run > Run All Cells
    page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()
    page.locator(".jp-NotebookPanel:visible .jp-OutputArea-output",
                 has_text="after a pause").wait_for(timeout=60_000)
    page.wait_for_timeout(4000)                                          # four autosave intervals


def test_running_a_shipped_notebook_leaves_git_clean(course_lab, artefacts):
    """A shipped notebook run past several autosaves is not written (git status stays empty, the file's bytes
    unchanged), while a notebook in work/ is autosaved as before."""
    from playwright.sync_api import sync_playwright
    repo, url, token = course_lab
    shipped = repo / "lectures" / "01_small.ipynb"
    before = shipped.read_bytes()
    own_before = (repo / "work" / "own.ipynb").read_bytes()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            _run_all(page, f"{url}/lab/tree/lectures/01_small.ipynb?reset&token={token}")
            page.screenshot(path=str(artefacts / "course-lab-shipped.png"))
            _run_all(page, f"{url}/lab/tree/work/own.ipynb?reset&token={token}")
        except Exception:
            page.screenshot(path=str(artefacts / "course-lab-failure.png"), full_page=True)
            raise
        finally:
            browser.close()
    status = subprocess.run(["git", "status", "--porcelain"], cwd=repo, capture_output=True, text=True).stdout
    assert status == "" and shipped.read_bytes() == before
    own = (repo / "work" / "own.ipynb").read_bytes()
    assert own != own_before and b"after a pause" in own                # autosave still works in work/


# ---- python -m course site: every page of the built site, in Chromium -----------------------------------------

def test_the_site_renders_every_lecture_with_its_figures(tmp_path, artefacts):
    """Build the site, open the index and every lecture page from disk in Chromium: every image loaded (a natural
    width above 0), every lecture linked from the index, no internal link broken; a screenshot of lecture 13."""
    pytest.importorskip("playwright.sync_api", reason="Playwright is missing: pip install playwright")
    pytest.importorskip("sphinx", reason='the site needs Sphinx: pip install -e ".[site]"')
    pytest.importorskip("myst_nb", reason='the site needs MyST-NB: pip install -e ".[site]"')
    if not Path(CHROMIUM).exists():
        pytest.skip(f"Chromium is missing at {CHROMIUM} (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    from course import site
    index = site.build_site(tmp_path / "site")
    assert site.check_links(index.parent) == []
    lectures = sorted((ROOT / "lectures").glob("[0-9][0-9]_*.ipynb"))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        try:
            page.goto(index.as_uri())
            hrefs = page.eval_on_selector_all("a", "els => els.map(e => e.getAttribute('href'))")
            for notebook in lectures:
                assert f"lectures/{notebook.stem}.html" in hrefs, notebook.stem
                page.goto((index.parent / "lectures" / f"{notebook.stem}.html").as_uri())
                page.wait_for_load_state("load")
                sizes = page.eval_on_selector_all("img", "els => els.map(e => [e.complete, e.naturalWidth])")
                assert sizes and all(done and width > 0 for done, width in sizes), (notebook.stem, sizes)
                assert page.locator("div.body h1").count() == 1                 # the lecture's title
            page.screenshot(path=str(artefacts / "site-lecture-13.png"))
        finally:
            browser.close()
