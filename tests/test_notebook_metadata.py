"""Opening a course notebook in JupyterLab and saving it leaves the file as committed (``git status`` clean, so a
later ``git pull`` of course updates does not conflict).

When a kernel starts, JupyterLab writes into the notebook's metadata the kernelspec of the kernel it started
(``display_name`` from the installed spec: "Python 3 (ipykernel)") and the kernel's ``language_info``; autosave
then writes the file as nbformat does (indent 1, keys sorted, UTF-8). The committed notebooks carry exactly that
metadata, so what JupyterLab writes is what is already there. ``language_info.version`` is the running Python's
and is left out of the comparison: a student on another Python version sees that one line change."""
import json
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted(p for folder in ("lectures", "exercises", "solutions") for p in (ROOT / folder).glob("*.ipynb"))

KERNELSPEC = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
LANGUAGE_INFO = {"codemirror_mode": {"name": "ipython", "version": 3}, "file_extension": ".py",
                 "mimetype": "text/x-python", "name": "python", "nbconvert_exporter": "python",
                 "pygments_lexer": "ipython3"}


def test_the_kernelspec_is_the_one_jupyter_installs():
    jupyter_client = pytest.importorskip("jupyter_client")
    spec = jupyter_client.kernelspec.KernelSpecManager().get_kernel_spec("python3")
    assert {"display_name": spec.display_name, "language": spec.language, "name": "python3"} == KERNELSPEC


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[f"{p.parent.name}/{p.name}" for p in NOTEBOOKS])
def test_opening_and_saving_a_notebook_changes_nothing(path):
    text = path.read_text(encoding="utf-8")
    nb = nbformat.reads(text, as_version=4)
    assert nb.metadata.get("kernelspec") == KERNELSPEC
    info = {k: v for k, v in nb.metadata.get("language_info", {}).items() if k != "version"}
    assert info == LANGUAGE_INFO
    opened = json.loads(text)                                              # what the kernel's start writes
    opened["metadata"]["kernelspec"] = dict(KERNELSPEC)
    opened["metadata"]["language_info"] = dict(LANGUAGE_INFO, version=nb.metadata.language_info["version"])
    saved = nbformat.writes(nbformat.from_dict(opened), version=4) + "\n"   # what autosave writes
    assert saved == text
