"""Every checked notebook output is the same on another CPU.

float32 results differ in their last digits between CPUs, and between torch's vectorised code paths on one
CPU, so a number printed from a float32 computation can flip on a student's laptop. The notebooks compute
every pinned number in float64 (README, "Notebook conventions"); this test proves it by re-running every
lecture and solution notebook with nbval in a second process where torch's vector kernels are replaced by
the plain ones (``ATEN_CPU_CAPABILITY=default``), MKL is held to SSE4.2, and everything runs on one thread,
and requiring the same outputs as the committed ones (which the normal nbval run checks under the machine's
own settings).

Deselect with ``pytest -m "not reproducibility"`` for a quick run.
"""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "lectures").glob("[0-9][0-9]_*.ipynb")) + sorted((ROOT / "solutions").glob("[0-9][0-9]_*.ipynb"))

ANOTHER_CPU = {
    "ATEN_CPU_CAPABILITY": "default",      # torch's scalar kernels instead of AVX2 / AVX-512 ones
    "MKL_ENABLE_INSTRUCTIONS": "SSE4_2",   # MKL's oldest code path
    "OMP_NUM_THREADS": "1",                # one thread: other reduction orders
    "MKL_NUM_THREADS": "1",
}


# The runs start a pytest of their own per lecture (its notebook and its solution in one process): without the
# plugins the run does not use, and without the IRI grammar jsonschema builds when nbformat imports it (about 1 s
# a process; notebook validation never checks an IRI). That saves about 3 s a notebook of process start.
_RUNNER = ("import sys; sys.modules['rfc3987_syntax'] = None; import pytest; "
           "sys.exit(pytest.main(sys.argv[1:]))")
_PLUGINS_OFF = ["-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:hypothesispytest", "-p", "no:timeout"]


def _nbval(notebooks: list[Path], env: dict, junit: Path) -> subprocess.CompletedProcess:
    command = [sys.executable, "-c", _RUNNER, *_PLUGINS_OFF, "-o", "addopts=", "-q", "--nbval", "--nbval-current-env",
               "--nbval-sanitize-with", str(ROOT / "tests" / "sanitize.cfg"), f"--junitxml={junit}",
               *map(str, notebooks)]
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=850)


def _seconds_per_notebook(junit: Path) -> dict:
    """{notebook path relative to the checkout: seconds} from the run's JUnit XML (each cell is a test case)."""
    import xml.etree.ElementTree as ET
    by_class = {p.relative_to(ROOT).as_posix().replace("/", "."): p.relative_to(ROOT).as_posix() for p in NOTEBOOKS}
    seconds = {}
    for case in ET.parse(junit).iter("testcase"):                     # classname: the path with dots for slashes
        notebook = by_class.get(case.get("classname", ""))
        if notebook:
            seconds[notebook] = seconds.get(notebook, 0.0) + float(case.get("time", 0))
    return seconds


LECTURES = sorted({p.name for p in NOTEBOOKS})                            # a lecture and its solution, by name


@pytest.mark.reproducibility
@pytest.mark.parametrize("name", LECTURES, ids=lambda n: n[:-len(".ipynb")])
def test_outputs_are_the_same_with_other_vector_code_and_one_thread(name, tmp_path, record_property):
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}   # notebooks draw with the inline backend
    env.update(ANOTHER_CPU, TQDM_DISABLE="1", PYTHONHASHSEED="0")
    notebooks = [p for p in NOTEBOOKS if p.name == name]
    result = _nbval(notebooks, env, tmp_path / "junit.xml")
    if (tmp_path / "junit.xml").exists():                               # each notebook's time, for the summary
        for notebook, seconds in _seconds_per_notebook(tmp_path / "junit.xml").items():
            record_property(f"as another CPU: {notebook}", seconds)
    assert result.returncode == 0, (f"{name} (lecture or solution) gives other outputs under {ANOTHER_CPU}:\n"
                                    + (result.stdout + result.stderr)[-6000:])


def test_another_cpu_really_is_another_code_path():
    """The settings above take effect in a child process (else the test above would prove nothing)."""
    env = dict(os.environ, **ANOTHER_CPU)
    probe = "import torch; print(torch.backends.cpu.get_cpu_capability(), torch.get_num_threads())"
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["DEFAULT", "1"]
