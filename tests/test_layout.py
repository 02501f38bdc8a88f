"""The package layout: the import graph of course/ has no cycles, the renderer never imports the course
machinery (grading, benchmarks), every command of ``python -m course`` names a module with a ``cli``, and
every subpackage is listed in pyproject.toml, so a wheel ships it.

The graph is read from the source with ``ast``, every import statement counted wherever it sits (module
level or inside a function): ``import course.x``, ``from course.x import y``, ``from .x import y`` and
``from . import x``, where ``from P import x`` names the submodule ``P.x`` when there is one and the package
``P`` otherwise. A submodule importing its own package's ``__init__`` is an edge like any other, so a
package that re-exports its submodules stays acyclic only while the submodules import each other, never the
package. (Importing ``P.x`` also runs ``P/__init__.py`` first; that implicit step is not an edge.)
"""
import ast
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "course"


def module_names() -> dict[str, Path]:
    """``{"course.grading.helpers": path, "course.grading": .../grading/__init__.py, ...}``."""
    names = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        names[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return names


def imported_modules(name: str, path: Path, known) -> set[str]:
    """The modules of course/ that the file of module ``name`` imports, anywhere in the file."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:                                                  # from .x import y, from .. import z
                base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1])
                base = f"{base}.{node.module}" if node.module else base
            else:
                base = node.module
            for alias in node.names:                                        # a submodule, or a name in base
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base)
    return {m for m in found if m in known and m != name}


def import_graph() -> dict[str, set[str]]:
    known = module_names()
    return {name: imported_modules(name, path, known) for name, path in known.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a path ``[a, b, ..., a]``, or None (depth-first search)."""
    state, stack = {}, []                                                   # state: 1 on the stack, 2 done

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_graph_sees_every_kind_of_import():
    graph = import_graph()
    assert "course.camera" in graph and "course.grading.lecture03" in graph and "course.bench.raster" in graph
    assert "course.tensors" in graph["course.camera"]                       # from .tensors import ...
    assert "course.raster" in graph["course.shading"]                       # inside a function
    assert "course.models" in graph["course"]
    assert {"course.grading.lecture01", "course.grading.grader"} <= graph["course.grading"]   # from . import x
    assert graph["course.grading.lecture03"] == {"course.grading.helpers", "course.grading.registry"}
    assert "course.raster" in graph["course.bench.raster"]                  # from ..raster import ...
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_course_has_no_import_cycles():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_renderer_does_not_import_the_course_machinery():
    graph = import_graph()
    renderer = [name for name, path in module_names().items()
                if path.parent == PACKAGE and path.name not in ("__init__.py", "__main__.py")]
    assert {"course.camera", "course.raster", "course.tensors", "course.models"} <= set(renderer)
    for name in renderer:
        reached, todo = set(), [name]
        while todo:                                                         # everything it imports, directly
            for nxt in graph[todo.pop()] - reached:                         # or through other modules
                reached.add(nxt)
                todo.append(nxt)
        machinery = sorted(m for m in reached if m.startswith(("course.grading", "course.bench")))
        assert not machinery, f"{name} imports {', '.join(machinery)}"


def test_every_command_names_a_module_with_a_cli():
    from course.__main__ import COMMANDS
    assert set(COMMANDS) == {"lab", "site", "render", "bench", "grade", "release", "workspace", "gradescope"}
    for name, (module, _) in COMMANDS.items():
        assert module in module_names(), name
        assert callable(importlib.import_module(module).cli), name


def test_every_subpackage_is_shipped():
    """pyproject.toml lists the packages a wheel holds: a new folder of modules must be added there."""
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text(encoding="utf-8"))
    packages = {name for name, path in module_names().items() if path.name == "__init__.py"}
    assert set(config["tool"]["setuptools"]["packages"]) == packages


def test_moved_modules_import_from_their_old_paths_with_a_warning_naming_the_new_one():
    """A notebook of an earlier term imports ``course.shadow_gradients``: it gets ``course.shadows.gradients``
    itself (the same functions, so graders that compare functions by identity see no difference) and a
    FutureWarning that says where to import it from; the module keeps its own name and spec."""
    import subprocess
    import sys
    from course._moved import MOVED
    probe = ("import importlib, json, warnings\n"
             "warnings.simplefilter('always')\n"
             f"moved = {MOVED!r}\n"
             "out = {}\n"
             "for old, new in moved.items():\n"
             "    with warnings.catch_warnings(record=True) as caught:\n"
             "        warnings.simplefilter('always')\n"
             "        module = importlib.import_module(old)\n"
             "    out[old] = [module is importlib.import_module(new), module.__name__, module.__spec__.name,\n"
             "                [(w.category.__name__, str(w.message)) for w in caught]]\n"
             "print(json.dumps(out))\n")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent)
    import json
    for old, (same, name, spec, caught) in json.loads(run.stdout).items():
        new = MOVED[old]
        assert same and name == new and spec == new, old
        assert caught == [["FutureWarning", f"{old} moved to {new}: import it from there"]], old
    for old, new in MOVED.items():                                         # the new place is real, the old gone
        assert new in module_names() and old not in module_names()
