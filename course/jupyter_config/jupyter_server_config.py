# JupyterLab's server settings for `python -m course lab` (course/lab.py): that command puts this folder first on
# JUPYTER_CONFIG_PATH for the lab it starts, and nowhere else. The shipped notebooks are served read-only (no
# autosave; Save As into work/), and the terminal is bash reading course/lab_bashrc, which puts the course's
# interpreter first on PATH after the user's own ~/.bashrc has run.
import os
import shutil

c = get_config()  # noqa: F821 (traitlets provides it)
c.ServerApp.contents_manager_class = "course.lab_contents.CourseContentsManager"
_bash = shutil.which("bash")
if _bash:
    c.ServerApp.terminado_settings = {
        "shell_command": [_bash, "--rcfile", os.path.join(os.path.dirname(os.path.dirname(__file__)), "lab_bashrc"),
                          "-i"]}
