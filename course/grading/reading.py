"""Reading a notebook's code without running it: what the grader and the teaching assistant learn from the text.

* ``reaches_reference`` is the grader's own reading of the reference rule (a graded function must not call the
  package function it re-implements). ``registry.calls_reference`` reads the live function, in the process that
  ran the notebook (``worker.py``), which is the student's to change; this reads the notebook's source in the
  grader's process, so that a notebook that disables the live reading there still meets the rule. A graded
  function reaches the reference when, following the notebook's own functions it calls by name, it uses a name
  bound to the reference (``from course.camera import look_at as f``; ``g = course.camera.look_at``), an attribute
  chain that spells it (``course.camera.look_at``, ``cam.look_at`` after ``import course.camera as cam``,
  ``Mesh(v, f).vertex_normals`` for a method), or, as the live reading does, mentions the reference's name while
  it uses any ``course`` module. A call hidden on purpose (``getattr`` with a built string, ``exec``) is not seen
  here either: reading the code shows it.
* ``worth_reading`` lists the lines a teaching assistant should read before trusting a score: code that reaches
  into the grader (``course.grading`` beyond ``check``), patches modules or builtins, registers IPython event
  callbacks, walks stack frames, forks, kills or signals processes, or reads ``/proc``. None of it can change a
  score (``sandbox.py``); it says what a student tried (``flags.py`` puts it in the report).
"""
from __future__ import annotations

import ast

from .release import _python_tree

__all__ = ["reaches_reference", "worth_reading"]


def _dotted(node) -> list[str] | None:
    """``a.b.c`` as ["a", "b", "c"]; a call's result as its function's chain plus "()"; else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Call):
        inner = _dotted(node.func)
        return None if inner is None else inner + ["()"] + parts[::-1]
    if isinstance(node, ast.Name):
        return [node.id] + parts[::-1]
    return None


class _Scope:
    """What each name is bound to, statement by statement: a dotted path into ``course`` ("course.camera.look_at"),
    a function the notebook defines (its node), or something else (None)."""

    def __init__(self, parent: "_Scope | None" = None):
        self.names: dict[str, object] = {}
        self.parent = parent

    def lookup(self, name: str):
        scope = self
        while scope is not None:
            if name in scope.names:
                return scope.names[name]
            scope = scope.parent
        return None

    def resolve(self, node) -> str | None:
        """The ``course`` path an expression spells, or None."""
        chain = _dotted(node)
        if not chain:
            return None
        root = self.lookup(chain[0])
        if not isinstance(root, str):
            return None
        rest = [p for p in chain[1:] if p != "()"]                     # Mesh(v, f).vertex_normals: Mesh.vertex_normals
        return ".".join([root] + rest)

    def bind(self, statement) -> None:
        """Record the names a statement binds."""
        if isinstance(statement, ast.Import):
            for alias in statement.names:
                if alias.asname:
                    self.names[alias.asname] = alias.name if alias.name.split(".")[0] == "course" else None
                else:
                    top = alias.name.split(".")[0]
                    self.names[top] = top if top == "course" else None
        elif isinstance(statement, ast.ImportFrom) and statement.module and not statement.level:
            inside = statement.module.split(".")[0] == "course"
            for alias in statement.names:
                self.names[alias.asname or alias.name] = f"{statement.module}.{alias.name}" if inside else None
        elif isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef)):
            self.names[statement.name] = statement
        elif isinstance(statement, ast.ClassDef):
            self.names[statement.name] = None
        elif isinstance(statement, (ast.Assign, ast.AnnAssign)):
            targets = statement.targets if isinstance(statement, ast.Assign) else [statement.target]
            value = self.resolve(statement.value) if statement.value is not None else None
            for target in targets:
                if isinstance(target, ast.Name):
                    self.names[target.id] = value


def _notebook_scope(sources: list[str]) -> _Scope:
    scope = _Scope()
    for source in sources:
        tree = _python_tree(source)
        for statement in tree.body if tree is not None else ():
            scope.bind(statement)
    return scope


def _function_reaches(fn, scope: _Scope, target: str, seen: set) -> bool:
    if id(fn) in seen:
        return False
    seen.add(id(fn))
    local = _Scope(scope)
    for node in ast.walk(fn):                                          # imports and aliases inside the function
        if isinstance(node, (ast.Import, ast.ImportFrom, ast.Assign, ast.AnnAssign)):
            local.bind(node)
    last = target.rsplit(".", 1)[-1]
    mentions = uses_course = False
    for node in ast.walk(fn):
        if isinstance(node, (ast.Name, ast.Attribute)):
            path = local.resolve(node)
            if path is not None:
                uses_course = True
                if path == target or path.startswith(target + "."):
                    return True
            name = node.id if isinstance(node, ast.Name) else node.attr
            if name == last and not (isinstance(node, ast.Name) and isinstance(local.lookup(name), ast.AST)):
                mentions = True
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            module = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
            uses_course |= bool(module) and module.split(".")[0] == "course"
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            helper = local.lookup(node.func.id)                         # a function of the notebook's: follow it
            if isinstance(helper, (ast.FunctionDef, ast.AsyncFunctionDef)) and _function_reaches(helper, scope,
                                                                                                  target, seen):
                return True
    return mentions and uses_course


def reaches_reference(sources: list[str], name: str, module: str, qualname: str) -> bool:
    """True when the notebook's function ``name`` (its last top-level ``def``) can reach ``module.qualname`` as
    its source reads (see the module docstring); ``sources``: the notebook's code cells in order."""
    scope = _notebook_scope(sources)
    fn = scope.lookup(name)
    if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
        return False
    target = f"{module}.{qualname}"
    if module.startswith("course.") and target.startswith("course."):
        return _function_reaches(fn, scope, target, set())
    return False


_PATCHED_MODULES = {"builtins", "torch", "numpy", "np", "json", "sys", "os", "math", "course", "IPython"}
_CALLS = {("events", "register"): "registers an IPython event callback",
          ("sys", "_getframe"): "walks the stack frames", ("inspect", "stack"): "walks the stack frames",
          ("inspect", "currentframe"): "walks the stack frames", ("os", "fork"): "forks a process",
          ("os", "setsid"): "starts a new session (a daemon)", ("os", "kill"): "signals a process",
          ("os", "killpg"): "signals a process group", ("ctypes", "CDLL"): "loads a C library",
          ("sys", "settrace"): "traces the interpreter", ("sys", "setprofile"): "traces the interpreter",
          ("gc", "get_objects"): "searches the interpreter's objects", ("os", "_exit"): "ends its process"}


def worth_reading(sources: list[str]) -> list[tuple[int, int, str]]:
    """(cell, line number, why) for each line of the notebook's code cells (``sources``, in order) that a teaching
    assistant should read (module docstring)."""
    aliases: dict[str, str] = {}
    found = []
    for cell, source in enumerate(sources):
        tree = _python_tree(source)
        if tree is None:
            continue
        lines: dict[int, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                aliases.update({a.asname or a.name.split(".")[0]: a.name if a.asname else a.name.split(".")[0]
                                for a in node.names})
            elif isinstance(node, ast.ImportFrom) and node.module:
                aliases.update({a.asname or a.name: f"{node.module}.{a.name}" for a in node.names})
        for node in ast.walk(tree):
            why = _why(node, aliases)
            if why and getattr(node, "lineno", None):
                lines.setdefault(node.lineno, why)
        found += [(cell, line, why) for line, why in sorted(lines.items())]
    return found


def _module_of(chain: list[str], aliases: dict[str, str]) -> str:
    """The dotted module path an attribute chain starts from, its first name read through the imports."""
    return ".".join([aliases.get(chain[0], chain[0])] + chain[1:]) if chain else ""


def _why(node, aliases: dict[str, str]) -> str | None:
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
        imported = [a.name for a in node.names] if isinstance(node, ast.ImportFrom) else []
        if any(n.startswith("course.grading") for n in names) and imported != ["check"]:
            return "imports the grader's internals"
    elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load):
        path = _module_of(_dotted(node) or [], aliases)
        if path.startswith("course.grading.") and not path.startswith("course.grading.check"):
            return "reaches into the grader"
    elif isinstance(node, (ast.Assign, ast.AugAssign, ast.Delete)):
        targets = node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]
        for target in targets:
            chain = _dotted(target) if isinstance(target, ast.Attribute) else None
            if chain and _module_of(chain, aliases).split(".")[0] in _PATCHED_MODULES:
                return f"patches {'.'.join(chain)}"
    elif isinstance(node, ast.Call):
        chain = _dotted(node.func) or []
        why = _CALLS.get(tuple(chain[-2:]))
        if why is None and chain[-1:] == ["setattr"] and node.args:
            first = _dotted(node.args[0]) or []
            why = f"patches {first[0]}" if first and _module_of(first, aliases).split(".")[0] in _PATCHED_MODULES \
                else None
        return why
    elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("/proc"):
        return "reads /proc"
    return None
