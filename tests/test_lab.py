"""``python -m course lab``: the shipped notebooks served read-only (so running a lecture in JupyterLab never
autosaves it and git stays clean), saves elsewhere unchanged, and a terminal whose ``python`` is the course's even
when ``~/.bashrc`` puts another first. The browser side (JupyterLab skipping autosave for a read-only notebook)
is in tests/test_browser.py, opt-in."""
import asyncio
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from course import lab
from course.lab_contents import CourseContentsManager

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("path, shipped", [
    ("lectures/01_representations_and_transforms.ipynb", True), ("solutions/13_x.ipynb", True),
    ("exercises/sub/03_x.ipynb", True), ("/lectures/01_x.ipynb", True), ("work/01_x.ipynb", False),
    ("lectures", False), ("lectures/notes.md", False), ("01_x.ipynb", False), ("workspace/lectures/x.ipynb", False)])
def test_which_notebooks_are_shipped(path, shipped, monkeypatch):
    monkeypatch.delenv("COURSE_EDIT_SHIPPED", raising=False)
    assert lab.is_shipped(path) is shipped
    monkeypatch.setenv("COURSE_EDIT_SHIPPED", "1")
    assert lab.is_shipped(path) is False


def _manager(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("1 + 1")])
    for folder in ("lectures", "work"):
        (tmp_path / folder).mkdir()
        nbformat.write(nb, tmp_path / folder / "01_x.ipynb")
    return CourseContentsManager(root_dir=str(tmp_path))


def test_a_shipped_notebook_is_read_only_and_refuses_a_save(tmp_path, monkeypatch):
    monkeypatch.delenv("COURSE_EDIT_SHIPPED", raising=False)
    manager = _manager(tmp_path)
    before = (tmp_path / "lectures" / "01_x.ipynb").read_bytes()
    model = asyncio.run(manager.get("lectures/01_x.ipynb"))
    assert model["writable"] is False and model["type"] == "notebook"
    model["content"]["cells"][0]["outputs"] = []
    from tornado import web
    with pytest.raises(web.HTTPError) as refused:
        asyncio.run(manager.save({"type": "notebook", "content": model["content"]}, "lectures/01_x.ipynb"))
    assert refused.value.status_code == 403 and "work/" in refused.value.log_message
    assert (tmp_path / "lectures" / "01_x.ipynb").read_bytes() == before
    # a copy into work/ and a student's own notebook save as usual
    saved = asyncio.run(manager.save({"type": "notebook", "content": model["content"]}, "work/01_copy.ipynb"))
    assert saved["path"] == "work/01_copy.ipynb" and (tmp_path / "work" / "01_copy.ipynb").is_file()
    assert asyncio.run(manager.get("work/01_x.ipynb"))["writable"] is True


def test_authors_can_edit_the_shipped_notebooks(tmp_path, monkeypatch):
    monkeypatch.setenv("COURSE_EDIT_SHIPPED", "1")
    manager = _manager(tmp_path)
    model = asyncio.run(manager.get("lectures/01_x.ipynb"))
    assert model["writable"] is True
    asyncio.run(manager.save({"type": "notebook", "content": model["content"]}, "lectures/01_x.ipynb"))


def test_the_launcher_puts_the_course_config_first(monkeypatch):
    monkeypatch.setenv("JUPYTER_CONFIG_PATH", "/somewhere/else")
    env = lab.lab_environment()
    assert env["JUPYTER_CONFIG_PATH"].split(os.pathsep) == [str(lab.CONFIG_DIR), "/somewhere/else"]
    assert env["COURSE_BIN"] == str(Path(sys.executable).parent)
    command = lab.lab_command(["--no-browser"])
    assert command[:4] == [sys.executable, "-m", "jupyter", "lab"] and command[-1] == "--no-browser"
    config = (lab.CONFIG_DIR / "jupyter_server_config.py").read_text()
    assert "course.lab_contents.CourseContentsManager" in config and "lab_bashrc" in config
    out = subprocess.run([sys.executable, "-m", "course", "lab", "--print-command"], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout
    assert "jupyter lab" in out and f"JUPYTER_CONFIG_PATH={lab.CONFIG_DIR}" in out


@pytest.mark.skipif(shutil.which("bash") is None, reason="the terminal's start-up file is for bash")
def test_the_terminal_finds_the_course_python_after_a_pyenv_bashrc(tmp_path):
    """A ~/.bashrc that puts a pyenv-style shim first, as the issue found: the lab's terminal still runs the
    interpreter that started the lab."""
    shims = tmp_path / "pyenv" / "shims"
    shims.mkdir(parents=True)
    (shims / "python").write_text("#!/bin/sh\necho not-the-course\n")
    (shims / "python").chmod(0o755)
    (tmp_path / ".bashrc").write_text(f'export PATH="{shims}:$PATH"\n')
    env = dict(os.environ, HOME=str(tmp_path), COURSE_BIN=str(Path(sys.executable).parent))
    plain = subprocess.run(["bash", "-i", "-c", "command -v python"], capture_output=True, text=True, env=env)
    assert plain.stdout.strip() == str(shims / "python")                # what the issue saw
    course = subprocess.run(["bash", "--rcfile", str(lab.BASHRC), "-i", "-c",
                             "python -c 'import sys, course; print(sys.executable)'"],
                            capture_output=True, text=True, env=env)
    assert Path(course.stdout.strip()).parent == Path(sys.executable).parent, course.stderr
