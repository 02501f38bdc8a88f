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


def _nbval(notebook: Path, env: dict) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-o", "addopts=", "-q", "--nbval",
               "--nbval-current-env", "--nbval-sanitize-with", str(ROOT / "tests" / "sanitize.cfg"), str(notebook)]
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=850)


@pytest.mark.reproducibility
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_outputs_are_the_same_with_other_vector_code_and_one_thread(notebook):
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}   # notebooks draw with the inline backend
    env.update(ANOTHER_CPU, TQDM_DISABLE="1", PYTHONHASHSEED="0")
    result = _nbval(notebook, env)
    assert result.returncode == 0, (f"{notebook.name} gives other outputs under {ANOTHER_CPU}:\n"
                                    + (result.stdout + result.stderr)[-6000:])


def test_another_cpu_really_is_another_code_path():
    """The settings above take effect in a child process (else the test above would prove nothing)."""
    env = dict(os.environ, **ANOTHER_CPU)
    probe = "import torch; print(torch.backends.cpu.get_cpu_capability(), torch.get_num_threads())"
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["DEFAULT", "1"]
