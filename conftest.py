"""How the whole suite runs: on every core, each notebook kept whole, and where the time went.

``pytest`` (pyproject's addopts) runs on up to four worker processes (pytest-xdist):

* a notebook's cells share one kernel and run in order, so nbval's items of one notebook form one unit of work,
  which one worker runs from start to end; so does each test module with expensive module-scoped fixtures
  (``WHOLE_MODULES``); every other test is handed out on its own, and the units go out longest first
  (``_order``: a long unit started last would leave the other core idle);
* a worker's own torch runs on one thread (the workers are the parallelism; notebook kernels and the
  reproducibility pass keep their own settings), and every process started from here lets idle OpenMP threads
  sleep (``OMP_WAIT_POLICY=PASSIVE``): spinning threads of two kernels on two cores cost lecture 09 61 s instead
  of 22 s when it shared the machine with lecture 13;
* the compiled kernels are warmed once, before the workers start, so that neither they nor the notebook
  kernels compile the same kernel at the same time;
* the summary ends with each notebook's time (its cells under nbval, and its second run as another CPU), so
  that growth shows (README, "Run every test").

Results do not depend on the split: no test reads another's output, and every notebook is one group.
"""
import os
import subprocess
import sys
from collections import defaultdict

import pytest


def _is_worker(config) -> bool:
    return hasattr(config, "workerinput")


def pytest_configure(config):
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")   # idle OpenMP threads sleep: workers and kernels share cores
    if config.pluginmanager.hasplugin("xdist"):
        config.pluginmanager.register(_Scheduler(), "course-notebook-scheduler")
    if _is_worker(config):
        import torch
        torch.set_num_threads(1)
    elif not getattr(config.option, "collectonly", False) and not os.environ.get("COURSE_SUITE_WARMED"):
        subprocess.run([sys.executable, "-c", "from course import kernels\nif kernels.available(): "
                        "kernels.warm_up()"], capture_output=True, env=dict(os.environ))
        os.environ["COURSE_SUITE_WARMED"] = "1"           # the reproducibility pass's pytest runs need not again


# Test modules whose module-scoped fixtures are expensive (a class graded, a wheel built and installed): each is
# one unit of work, so that its fixtures are made once, not once per worker.
WHOLE_MODULES = {f"tests/{name}.py" for name in (
    "test_grading_attacks", "test_gradescope", "test_grader_class", "test_gradebook", "test_flags", "test_grading",
    "test_remote", "test_fit", "test_fit_images", "test_fit_texture", "test_fit_views", "test_learn", "test_mvtn",
    "test_shadow_art", "test_shapes", "test_viz_fit")}
REPRODUCIBLE = "tests/test_notebooks_reproducible.py::test_outputs_are_the_same_with_other_vector_code_and_one_thread["


def _scope(nodeid: str) -> str:
    """The unit of work a test belongs to: its notebook, its module (``WHOLE_MODULES``), or itself."""
    path = nodeid.split("::")[0]
    return path if path.endswith(".ipynb") or path in WHOLE_MODULES else nodeid


def _order(scope: str, size: int):
    """Longest first, so that no long unit starts last: the grading attacks (about 150 s), the reproducibility
    runs (a lecture and its solution each; later lectures are longer), the notebooks (most cells first), the
    other whole modules, then every other test in collection order."""
    if scope == "tests/test_grading_attacks.py":
        return (0, 0)
    if scope.startswith(REPRODUCIBLE):
        number = scope[len(REPRODUCIBLE):len(REPRODUCIBLE) + 2]
        return (1, -int(number) if number.isdigit() else 0)
    if scope.endswith(".ipynb"):
        return (2, -size)
    if scope in WHOLE_MODULES:
        return (3, -size)
    return (4, 0)


class _Scheduler:
    """Work units (``_scope``) handed out longest first (``_order``)."""

    @staticmethod
    def pytest_xdist_make_scheduler(config, log):
        from xdist.scheduler import LoadScopeScheduling

        class CourseScheduling(LoadScopeScheduling):
            def _split_scope(self, nodeid):
                return _scope(nodeid)

            def schedule(self):
                """LoadScopeScheduling.schedule with the work queue in ``_order``."""
                assert self.collection_is_completed
                if self.collection is not None:
                    for node in self.nodes:
                        self._reschedule(node)
                    return
                if not self._check_nodes_have_same_collection():
                    self.log("**Different tests collected, aborting run**")
                    return
                self.collection = list(next(iter(self.registered_collections.values())))
                if not self.collection:
                    return
                units = {}
                for nodeid in self.collection:
                    units.setdefault(self._split_scope(nodeid), {})[nodeid] = False
                for scope, nodeids in sorted(units.items(), key=lambda item: _order(item[0], len(item[1]))):
                    self.workqueue[scope] = nodeids
                for _ in range(max(0, len(self.nodes) - len(self.workqueue))):
                    unused, _assigned = self.assigned_work.popitem()
                    unused.shutdown()
                for node in self.nodes:
                    self._assign_work_unit(node)
                for node in self.nodes:
                    self._reschedule(node)
                if not self.workqueue:
                    for node in self.nodes:
                        node.shutdown()
        return CourseScheduling(config, log)


_NOTEBOOK_TIMES = defaultdict(float)


def pytest_runtest_logreport(report):
    """Add up each notebook's time: its nbval cells, and its share of its lecture's reproducibility run."""
    path = report.nodeid.split("::")[0]
    if path.endswith(".ipynb"):
        _NOTEBOOK_TIMES[(path, "nbval")] += report.duration
    elif "test_outputs_are_the_same_with_other_vector_code_and_one_thread[" in report.nodeid and report.when == "call":
        for key, seconds in report.user_properties:                    # one run: a lecture and its solution
            if key.startswith("as another CPU: "):
                _NOTEBOOK_TIMES[(key[len("as another CPU: "):], "as another CPU")] += seconds


@pytest.hookimpl(trylast=True)
def pytest_terminal_summary(terminalreporter):
    if not _NOTEBOOK_TIMES:
        return
    rows = defaultdict(dict)
    for (path, run), seconds in _NOTEBOOK_TIMES.items():
        rows[path][run] = seconds
    terminalreporter.section("notebook times (seconds)")
    terminalreporter.write_line(f"{'notebook':54s} {'nbval':>7s} {'as another CPU':>15s}")
    for path in sorted(rows, key=lambda p: -sum(rows[p].values())):
        times = rows[path]
        terminalreporter.write_line(f"{path:54s} {times.get('nbval', 0):7.1f} {times.get('as another CPU', 0):15.1f}")
    terminalreporter.write_line(f"{'all':54s} {sum(t.get('nbval', 0) for t in rows.values()):7.1f} "
                                f"{sum(t.get('as another CPU', 0) for t in rows.values()):15.1f}")
