"""Copy flags for the teaching assistant: graded functions that read like the package's code, or like each other.

The graded functions re-implement package functions, and the package ships to students: calling the reference
scores 0 (``registry.calls_reference``), but pasting its code passes. ``find_flags`` compares each graded function
of each notebook with the package function it re-implements (``Task.reference``), with the solution notebook's
function where the course's ``solutions/`` is at hand, and with the same function of every other notebook in the
run, and ``write_report`` lists each pair at or above a threshold with the matching lines side by side. It
flags; a person decides. Scores are never changed.

How two functions are compared
------------------------------
1. The function is cut out of the notebook: the last top-level ``def`` of its name, the one the grader finds.
2. It is written in a canonical form (``canonical``): its syntax tree with docstrings dropped, trivial arithmetic
   folded (``x * 1``, ``0 + x``, ``2 * 0.5``, ``-(-x)``), ``x += y`` written ``x = x + y``, names bound by ``from
   m import n [as k]`` (in the function or anywhere in the notebook) written ``m.n``, and each run of independent
   assignments put in one order, then written out again (``ast.unparse``), so redundant parentheses and layout
   are gone.
3. That becomes a stream of tokens (``tokens_of``): comments and blank lines are gone; every identifier becomes
   ``_``, so renaming variables (or ``import torch as T``) changes nothing; attribute names (``.norm``),
   keyword-argument names (``dim=``), keywords, operators and numbers stay (``1.0`` and ``1`` alike); every string
   becomes one placeholder. Each token keeps the source line it came from, for the report.
4. The exercise's own code (the signature, code given around ``# YOUR CODE HERE``) is taken out of a student's
   stream, since every student starts from it.
5. ``similarity`` tiles the two streams greedily with the longest common runs of at least ``RUN`` tokens,
   anywhere and in any order (greedy string tiling, as in JPlag), and divides the tokens covered by the length
   of the shorter stream: 1.0 means all of one function appears in the other, in runs of ``RUN`` tokens or more.
6. A function with fewer than ``MIN_TOKENS`` tokens of the student's own (``return points @ R.T + t``) cannot
   tell copying from the one way to write it: it is listed as not compared. Nor is any answer to a formula task,
   one whose course answer (the solution notebook's, else the package's) has fewer than ``FORMULA_TOKENS``: two
   honest students write 11.1's ``F @ F.T / (H * W)`` alike.

``THRESHOLD`` (0.65) is set from measurements on this course's code (``tests/test_flags.py``): each of the 45
package references pasted with its variables renamed and its docstring and comments dropped scores 0.88-1.00
against the reference; a classmate's code with every name changed and every operand in parentheses of its own
scores 1.00 (0.21-0.68 before step 2); eight correct solutions written independently and differently (two each of
four tasks) score at most 0.47 against the reference, the solution notebook and each other. 0.65 sits in the
middle of the gap, a little towards fewer flags, since a class of 300 makes 45,000 pairs per task. (The course's
own solution notebooks, written from the package by its author, score up to 0.94 against it: they are flagged,
rightly.) Reordered arguments and commuted operands (``a * b`` for ``b * a``) are not normalised: each breaks a
run for a token or two.

The report also lists the code worth reading (``reading.worth_reading``): lines that reach into the grader, patch
modules or builtins, register IPython callbacks, walk stack frames, fork or signal processes.
"""
from __future__ import annotations

import ast
import difflib
import importlib
import inspect
import io
import keyword
import textwrap
import tokenize
from dataclasses import dataclass, field
from pathlib import Path

from .reading import worth_reading
from .registry import TASKS, Task, tasks_for_lecture
from .submissions import _lecture_number

__all__ = ["THRESHOLD", "RUN", "MIN_TOKENS", "FORMULA_TOKENS", "Code", "Flag", "tokens_of", "similarity", "tiles", "function_source",
           "notebook_code", "reference_code", "find_flags", "write_report"]

THRESHOLD = 0.65        # pairs at or above this similarity are flagged
RUN = 8                 # the shortest run of tokens that counts as shared (shorter runs happen by chance)
MIN_TOKENS = 25         # functions shorter than this (own tokens) are too short to compare
FORMULA_TOKENS = 60     # tasks whose own answer is shorter than this are formulas: not compared at all

_DROPPED = {tokenize.COMMENT, tokenize.NL, tokenize.ENCODING, tokenize.ENDMARKER}
_FSTRING_START = getattr(tokenize, "FSTRING_START", None)       # Python 3.12 splits f-strings into tokens
_FSTRING_END = getattr(tokenize, "FSTRING_END", None)
_STRING = "'…'"                                                  # every string literal


# ------------------------------------------------------------------------------------ code as tokens

@dataclass(frozen=True)
class Code:
    """One function, ready to compare. ``who``: a student, or ``package course.camera.look_at``; ``where``: the
    notebook and cell (or the package file); ``lines``: its source lines as written; ``tokens``: the normalised
    stream, and ``rows[k]`` the index into ``lines`` of token k."""
    who: str
    where: str
    lines: tuple[str, ...]
    tokens: tuple[str, ...]
    rows: tuple[int, ...]


def _docstring_spans(tree: ast.AST) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) positions of the statements that are a string alone: docstrings, and strings used as
    comments."""
    return [((node.lineno, node.col_offset), (node.end_lineno, node.end_col_offset)) for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)]


def _number(text: str) -> str:
    """``1e-12``, ``1E-12`` and ``0.000000000001`` alike; ``1.0`` and ``1`` alike."""
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text
    if isinstance(value, float) and value.is_integer() and abs(value) < 2 ** 53:
        value = int(value)
    return repr(value)


def tokens_of(source: str) -> tuple[list[str], list[int]]:
    """The normalised tokens of one function's ``source`` and the 0-based source line of each (see the module
    docstring, step 2)."""
    spans = _docstring_spans(ast.parse(source))
    raw = [t for t in tokenize.generate_tokens(io.StringIO(source).readline) if t.type not in _DROPPED]
    raw = [t for t in raw if not any(start <= t.start and t.end <= end for start, end in spans)]
    tokens: list[str] = []
    rows: list[int] = []
    depth = fstring = 0                                           # bracket depth; f-string nesting (3.12)
    for k, tok in enumerate(raw):
        if tok.type == _FSTRING_START:
            fstring += 1
            continue
        if fstring:
            if tok.type == _FSTRING_END:
                fstring -= 1
                if not fstring:
                    tokens.append(_STRING)
                    rows.append(tok.start[0] - 1)
            continue
        text = tok.string
        if tok.type == tokenize.NEWLINE:
            if not tokens or tokens[-1] in ("NEWLINE", "INDENT", "DEDENT"):
                continue                                          # a statement that was a docstring
            text = "NEWLINE"
        elif tok.type in (tokenize.INDENT, tokenize.DEDENT):
            text = tokenize.tok_name[tok.type]
        elif tok.type == tokenize.STRING:
            text = _STRING
        elif tok.type == tokenize.NUMBER:
            text = _number(text)
        elif tok.type == tokenize.NAME and not keyword.iskeyword(text):
            after_dot = bool(tokens) and tokens[-1] == "."
            next_is_equals = k + 1 < len(raw) and raw[k + 1].string == "="
            if not after_dot and not (depth > 0 and next_is_equals):  # attributes and f(dim=...) stay
                text = "_"
        elif tok.type == tokenize.OP:
            depth += (text in "([{") - (text in ")]}")
        tokens.append(text)
        rows.append(tok.start[0] - 1)
    for k in range(len(tokens) - 2, -1, -1):
        if tokens[k] == "INDENT":                                 # on the line it indents, not a docstring's
            rows[k] = rows[k + 1]
    last = len(source.splitlines()) - 1
    for k in range(1, len(tokens)):
        if tokens[k] == "DEDENT" and rows[k] > last:              # the dedents after the last line: on it
            rows[k] = rows[k - 1]
    return tokens, rows


def _lines(tokens: list[str], rows: list[int]) -> list[tuple[int, str]]:
    """(row, its tokens as one string) for each source line that has tokens; indentation tokens left out, as they
    belong to whichever line follows a block."""
    by_row: dict[int, list[str]] = {}
    for token, row in zip(tokens, rows):
        if token not in ("INDENT", "DEDENT"):
            by_row.setdefault(row, []).append(token)
    return [(row, " ".join(words)) for row, words in sorted(by_row.items())]


# ---------------------------------------------------------------------------- a canonical form of the code

class _Canonical(ast.NodeTransformer):
    """Rewrites that leave the program as it was: docstrings dropped, trivial arithmetic folded (``x * 1``, ``0 +
    x``, ``2 * 0.5``, ``-(-x)``), ``x += y`` written ``x = x + y``, names bound by ``from m import n [as k]``
    written ``m.n``, and each run of independent assignments put in one order (``_reorder``). Redundant
    parentheses and layout go when the tree is written out again (``ast.unparse``)."""

    def __init__(self, aliases: dict[str, str]):
        self.aliases = aliases                                         # k -> "m.n"

    def visit_Name(self, node):
        dotted = self.aliases.get(node.id)
        if dotted is None or not isinstance(node.ctx, ast.Load):
            return node
        parts = dotted.split(".")
        value: ast.expr = ast.Name(parts[0], ast.Load())
        for part in parts[1:]:
            value = ast.Attribute(value, part, ast.Load())
        return ast.copy_location(value, node)

    def visit_UnaryOp(self, node):
        self.generic_visit(node)
        if isinstance(node.op, ast.UAdd):
            return node.operand
        if isinstance(node.op, ast.USub) and isinstance(node.operand, ast.UnaryOp) and isinstance(
                node.operand.op, ast.USub):
            return node.operand.operand
        return node

    def visit_BinOp(self, node):
        self.generic_visit(node)
        left, right = (_number_of(node.left), _number_of(node.right))
        if left is not None and right is not None and not isinstance(node.op, (ast.Pow, ast.LShift)):
            try:
                value = eval(compile(ast.Expression(node), "<fold>", "eval"), {"__builtins__": {}})  # numbers only
            except Exception:                                          # 1 / 0, ...: leave it as written
                return node
            if isinstance(value, (int, float)) and value >= 0:
                return ast.copy_location(ast.Constant(value), node)
            return node
        identity = {ast.Mult: 1, ast.Div: 1, ast.Add: 0, ast.Sub: 0, ast.Pow: 1, ast.FloorDiv: 1}.get(type(node.op))
        if identity is not None and right == identity:
            return node.left
        if isinstance(node.op, (ast.Mult, ast.Add)) and left == identity:
            return node.right
        return node

    def visit_AugAssign(self, node):
        self.generic_visit(node)
        if not isinstance(node.target, ast.Name):
            return node
        value = ast.BinOp(ast.Name(node.target.id, ast.Load()), node.op, node.value)
        return ast.copy_location(ast.Assign([node.target], value), node)

    def generic_visit(self, node):
        super().generic_visit(node)
        for name in ("body", "orelse", "finalbody"):
            block = getattr(node, name, None)
            if isinstance(block, list) and block and isinstance(block[0], ast.stmt):
                block = [s for s in block if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant)
                                                  and isinstance(s.value.value, str))] or [ast.Pass()]
                setattr(node, name, _reorder(block))
        return node


def _number_of(node):
    """The value of a plain number literal (``2``, ``0.5``; not ``True``), else None."""
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return node.value
    return None


def _names(node, ctx) -> set[str]:
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and isinstance(n.ctx, ctx)}


def _reorder(block: list[ast.stmt]) -> list[ast.stmt]:
    """Each run of consecutive assignments to plain names, in a canonical order that keeps every dependency
    (a statement after another that writes what it reads or reads what it writes): among the statements free to
    go next, the one whose code, with every name erased, sorts first."""
    out, run = [], []
    for statement in block + [None]:
        simple = isinstance(statement, ast.Assign) and all(
            isinstance(t, (ast.Name, ast.Tuple)) and all(isinstance(e, ast.Name) for e in ast.walk(t)
                                                          if isinstance(e, ast.expr) and e is not t)
            for t in statement.targets)
        if simple:
            run.append(statement)
            continue
        if run:
            out += _canonical_order(run)
            run = []
        if statement is not None:
            out.append(statement)
    return out


def _canonical_order(run: list[ast.stmt]) -> list[ast.stmt]:
    writes = [set().union(*(_names(t, ast.Store) for t in s.targets)) for s in run]
    reads = [_names(s.value, ast.Load) for s in run]
    keys = [" ".join(tokens_of(ast.unparse(s))[0]) for s in run]
    after = {j: {i for i in range(j) if writes[i] & (reads[j] | writes[j]) or writes[j] & reads[i]}
             for j in range(len(run))}
    placed: list[int] = []
    while len(placed) < len(run):
        free = [j for j in range(len(run)) if j not in placed and after[j] <= set(placed)]
        placed.append(min(free, key=lambda j: (keys[j], j)))
    return [run[j] for j in placed]


def _statements(node):
    """Every statement under ``node``, in the order they are written."""
    for name in ("body", "orelse", "finalbody", "handlers", "cases"):
        for child in getattr(node, name, None) or ():
            if isinstance(child, ast.stmt):
                yield child
            yield from _statements(child)


def canonical(source: str, aliases: dict[str, str] | None = None) -> tuple[str, list[int]]:
    """``source`` in the canonical form of ``_Canonical``, and for each of its lines the 0-based line of
    ``source`` it comes from (the first line of the statement written there)."""
    tree = _Canonical(aliases or {}).visit(ast.parse(source))
    ast.fix_missing_locations(tree)
    text = ast.unparse(tree) + "\n"
    origin = [max(0, getattr(s, "lineno", 1) - 1) for s in _statements(tree)]
    again = list(_statements(ast.parse(text)))
    rows = [0] * len(text.splitlines())
    for statement, row in zip(again, origin):
        for line in range(statement.lineno - 1, statement.end_lineno):
            rows[line] = row
    return text, rows


def _aliases(tree) -> dict[str, str]:
    """``k`` -> ``"m.n"`` for every ``from m import n as k`` in ``tree`` (relative imports left out)."""
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                if alias.name != "*":
                    found[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return found


def canonical_tokens(source: str, aliases: dict[str, str] | None = None) -> tuple[list[str], list[int]]:
    """``tokens_of`` the canonical form of ``source`` (``canonical``), each token's row a line of ``source``."""
    source = textwrap.dedent(source)
    aliases = dict(aliases or {}, **_aliases(ast.parse(source)))
    text, origin = canonical(source, aliases)
    tokens, rows = tokens_of(text)
    return tokens, [origin[min(r, len(origin) - 1)] if origin else 0 for r in rows]


def template_lines(source: str) -> list[str]:
    """The exercise's version of a graded function (``# YOUR CODE HERE`` and its ``raise NotImplementedError()``
    included, so an unattempted function is left with nothing of its own) as normalised lines, for ``_code``."""
    return [line for _, line in _lines(*canonical_tokens(source))]


def _code(who: str, where: str, source: str, template: list[str] | None = None,
          aliases: dict[str, str] | None = None) -> Code:
    """``source`` as a ``Code`` (its canonical tokens, ``canonical_tokens``; ``aliases``: the notebook's
    ``from m import n`` names). With ``template`` (``template_lines`` of the exercise), the lines it shares with the
    exercise, matched in order (difflib), are taken out: the signature and any code the exercise gives."""
    source = textwrap.dedent(source)
    tokens, rows = canonical_tokens(source, aliases)
    if template:
        lines = _lines(tokens, rows)
        matcher = difflib.SequenceMatcher(None, template, [line for _, line in lines], autojunk=False)
        given = {lines[j + k][0] for _, j, size in matcher.get_matching_blocks() for k in range(size)}
        kept = [k for k in range(len(tokens)) if rows[k] not in given]
        tokens, rows = [tokens[k] for k in kept], [rows[k] for k in kept]
    return Code(who, where, tuple(source.splitlines()), tuple(tokens), tuple(rows))


# ------------------------------------------------------------------------------- comparing two streams

def tiles(a, b, run: int = RUN) -> list[tuple[int, int, int]]:
    """Greedy string tiling: (i, j, size) with ``a[i:i+size] == b[j:j+size]``, no token in two tiles, each at
    least ``run`` long, longest first. Each round finds the longest runs among the tokens not yet tiled and
    tiles them, until none is ``run`` long. Candidates start where a's next ``run`` tokens occur in b."""
    a, b = list(a), list(b)
    where_in_b: dict[tuple, list[int]] = {}
    for j in range(len(b) - run + 1):
        where_in_b.setdefault(tuple(b[j:j + run]), []).append(j)
    used_a, used_b = [False] * len(a), [False] * len(b)
    found = []
    while True:
        best, matches = run - 1, []
        for i in range(len(a) - run + 1):
            for j in where_in_b.get(tuple(a[i:i + run]), ()):
                size = 0
                while (i + size < len(a) and j + size < len(b) and a[i + size] == b[j + size]
                       and not used_a[i + size] and not used_b[j + size]):
                    size += 1
                if size > best:
                    best, matches = size, [(i, j, size)]
                elif size == best:
                    matches.append((i, j, size))
        if best < run:
            return sorted(found)
        for i, j, size in matches:                               # equally long runs, unless they overlap
            if not any(used_a[i:i + size]) and not any(used_b[j:j + size]):
                used_a[i:i + size], used_b[j:j + size] = [True] * size, [True] * size
                found.append((i, j, size))


def _grams(tokens) -> list[tuple]:
    """Every run of ``RUN`` consecutive tokens, in order."""
    return [tuple(tokens[i:i + RUN]) for i in range(len(tokens) - RUN + 1)]


def _covered(grams: list[tuple], other: set, length: int) -> int:
    """How many of ``length`` tokens lie in a run of ``RUN`` (``grams``) that also occurs in ``other``."""
    hit = [False] * length
    for i, gram in enumerate(grams):
        if gram in other:
            hit[i:i + RUN] = [True] * RUN
    return sum(hit)


def _bound(a: Code, b: Code, grams: dict) -> float:
    """An upper bound of ``similarity(a, b)``: the share of the shorter stream's tokens that lie in a run of
    ``RUN`` tokens found somewhere in the other. Cheap, so most pairs of a large class skip the tiling.
    ``grams``: id(code) -> (its runs in order, as a set), computed once per function."""
    shorter = min(len(a.tokens), len(b.tokens))
    if not shorter:
        return 0.0
    (a_list, a_set), (b_list, b_set) = grams[id(a)], grams[id(b)]
    return min(_covered(a_list, b_set, len(a.tokens)), _covered(b_list, a_set, len(b.tokens))) / shorter


def similarity(a: Code, b: Code) -> tuple[float, list[tuple[int, int, int]]]:
    """(tokens of the shorter stream covered by shared runs / its length, the tiles), in [0, 1]."""
    shorter = min(len(a.tokens), len(b.tokens))
    if not shorter:
        return 0.0, []
    found = tiles(a.tokens, b.tokens)
    return sum(size for _, _, size in found) / shorter, found


# ------------------------------------------------------------------------------ where the code comes from

def function_source(nb, name: str) -> tuple[str, int] | None:
    """(source, cell index) of the last top-level ``def name`` in the notebook's code cells, or None."""
    from .release import _python_tree               # magics and shell lines blanked, line numbers kept

    found = None
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        tree = _python_tree(cell.source)
        if tree is None:
            continue
        lines = cell.source.splitlines()
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == name:
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                found = ("\n".join(lines[first - 1:node.end_lineno]) + "\n", index)
    return found


def notebook_code(nb, task: Task, who: str, where: str, template: list[str] | None = None) -> Code | None:
    """The student's function of ``task`` in ``nb`` as a ``Code`` (None: not defined, or not Python)."""
    found = function_source(nb, task.name)
    if found is None:
        return None
    source, cell = found
    from .release import _python_tree
    aliases: dict[str, str] = {}
    for other in nb.cells:                                      # the notebook's from-imports, in cell order
        tree = _python_tree(other.source) if other.cell_type == "code" else None
        aliases.update(_aliases(tree) if tree is not None else {})
    try:
        return _code(who, f"{where}, cell {cell}", source, template, aliases)
    except (SyntaxError, tokenize.TokenError, ValueError):
        return None


def reference_code(task: Task) -> Code | None:
    """The package function ``task`` re-implements, as a ``Code`` (None: the task has none)."""
    if task.reference is None:
        return None
    module, qualname = task.reference
    try:
        value = importlib.import_module(module)
        for part in qualname.split("."):
            value = getattr(value, part)
        value = inspect.unwrap(value)
        source, path = inspect.getsource(value), inspect.getsourcefile(value)
    except (ImportError, AttributeError, OSError, TypeError):
        return None
    return _code(f"package {module}.{qualname}", str(path), source)


def _course_notebook(folder: str, lecture: int, roots: list[Path]):
    """``folder/NN_*.ipynb`` (exercises or solutions) under the first of ``roots`` that has one, read; or None."""
    import nbformat
    for root in roots:
        for path in sorted((root / folder).glob(f"{lecture:02d}_*.ipynb")):
            return path, nbformat.read(str(path), as_version=4)
    return None


# ------------------------------------------------------------------------------------------- the run

@dataclass(frozen=True)
class Flag:
    """A pair at or above the threshold on one task: ``left`` is a student, ``right`` the package, the solution
    notebook or another student; ``tiles`` index their token streams (see ``tiles``)."""
    task: str
    name: str
    similarity: float
    left: Code
    right: Code
    tiles: list[tuple[int, int, int]] = field(repr=False)


@dataclass
class Flags:
    """What ``find_flags`` found: the flags, most similar first; per task, the students too short to compare, those
    whose notebook has no ``def`` of the function (defined another way: ``exec``, an import, a deleted cell) and the
    references compared against; notes (no exercise template found, ...)."""
    flags: list[Flag]
    threshold: float
    too_short: dict[str, list[str]]
    not_found: dict[str, list[str]]
    references: dict[str, list[str]]
    notes: list[str]
    formulas: dict[str, int] = field(default_factory=dict)
    worth_reading: list[tuple[str, str, int, str, str]] = field(default_factory=list)


def _roots() -> list[Path]:
    """Where the course's exercises/ and solutions/ may be: the working directory, then the checkout that holds
    this package."""
    return list(dict.fromkeys([Path.cwd(), Path(__file__).resolve().parents[2]]))


def find_flags(notebooks, threshold: float = THRESHOLD) -> Flags:
    """Compare every graded function of ``notebooks``, a list of (who, path), with its references and with each
    other (see the module docstring). Nothing is run: the notebooks are only read."""
    import nbformat

    by_lecture: dict[int, list[tuple[str, Path, object]]] = {}
    notes = []
    for who, path in notebooks:
        lecture = _lecture_number(Path(path))
        if lecture is None or not tasks_for_lecture(lecture):
            continue
        try:
            nb = nbformat.read(str(path), as_version=4)
        except Exception as exc:                                     # not a notebook: nothing to compare
            notes.append(f"{path}: not read ({type(exc).__name__})")
            continue
        by_lecture.setdefault(lecture, []).append((who, Path(path), nb))
    result = Flags([], threshold, {}, {}, {}, notes)
    for lecture, entries in sorted(by_lecture.items()):
        for who, path, nb in entries:
            cells = [(index, cell.source) for index, cell in enumerate(nb.cells) if cell.cell_type == "code"]
            for k, row, why in worth_reading([source for _, source in cells]):
                lines = cells[k][1].splitlines()
                result.worth_reading.append((who, str(path), cells[k][0], lines[row - 1].strip(), why))
    for lecture, entries in sorted(by_lecture.items()):
        for task in tasks_for_lecture(lecture):
            _flag_task(task, lecture, entries, result)
    result.flags.sort(key=lambda f: (-f.similarity, f.task, f.left.who, f.right.who))
    return result


def _flag_task(task: Task, lecture: int, entries, result: Flags) -> None:
    """Add the flags of one task to ``result``: each student against the references, then each pair."""
    exercise, solution = _course_notebook("exercises", lecture, _roots()), _course_notebook("solutions", lecture,
                                                                                            _roots())
    template = None
    if exercise is not None:
        found = function_source(exercise[1], task.name)
        template = template_lines(found[0]) if found else None
    elif task.id == tasks_for_lecture(lecture)[0].id:
        result.notes.append(f"lecture {lecture:02d}: no exercises/{lecture:02d}_*.ipynb found, so the exercise's "
                            "own lines (signatures, given code) count as shared")
    references = [reference_code(task)]
    if solution is not None:
        references.append(notebook_code(solution[1], task, "solution notebook", str(solution[0]), template))
    references = [r for r in references if r is not None and r.tokens]
    result.references[task.id] = [r.who for r in references]
    students, short, not_found = [], [], []
    for who, path, nb in entries:
        code = notebook_code(nb, task, who, str(path), template)
        if code is None:
            not_found.append(who)
        elif len(code.tokens) >= MIN_TOKENS:
            students.append(code)
        elif code.tokens:                                         # nothing of their own: not attempted
            short.append(code)
    answer = next((r for r in references if r.who == "solution notebook"), references[0] if references else None)
    if answer is not None and len(answer.tokens) < FORMULA_TOKENS:      # a formula: everyone writes it alike
        result.formulas[task.id] = len(answer.tokens)
        short, students = short + students, []
    result.too_short[task.id], result.not_found[task.id] = [c.who for c in short], not_found
    pairs = [(s, r) for s in students for r in references]
    pairs += [(a, b) for k, a in enumerate(students) for b in students[k + 1:]]
    grams = {id(code): (runs, set(runs)) for code in students + references for runs in [_grams(code.tokens)]}
    for a, b in pairs:
        if min(len(a.tokens), len(b.tokens)) < MIN_TOKENS or _bound(a, b, grams) < result.threshold:
            continue                                              # a reference too short to tell, or far apart
        score, found = similarity(a, b)
        if score >= result.threshold:
            result.flags.append(Flag(task.id, task.name, score, a, b, found))


# ---------------------------------------------------------------------------------------------- report

def _side_by_side(flag: Flag, width: int = 60) -> list[str]:
    """The matching lines of the pair, left and right, one block per group of tiles that follow each other."""
    def span(code: Code, start: int, size: int) -> list[int]:
        """The first and last line whose first word the tile holds (a tile may start at a line's last bracket)."""
        first_word: dict[int, int] = {}
        for k, (token, row) in enumerate(zip(code.tokens, code.rows)):
            if token not in ("NEWLINE", "INDENT", "DEDENT"):
                first_word.setdefault(row, k)
        rows = sorted(row for row, k in first_word.items() if start <= k < start + size) or [code.rows[start]]
        return [rows[0], rows[-1]]

    blocks: list[list[int]] = []                                  # [left first, left last, right first, last]
    for i, j, size in sorted(flag.tiles):
        rows = span(flag.left, i, size) + span(flag.right, j, size)
        last = blocks[-1] if blocks else None
        if last and rows[0] <= last[1] + 1 and last[2] <= rows[2] <= last[3] + 1:
            last[1], last[3] = max(last[1], rows[1]), max(last[3], rows[3])
        else:
            blocks.append(rows)
    out = []
    for left_first, left_last, right_first, right_last in blocks:
        left = flag.left.lines[left_first:left_last + 1]
        right = flag.right.lines[right_first:right_last + 1]
        for k in range(max(len(left), len(right))):
            a = left[k].rstrip() if k < len(left) else ""
            b = right[k].rstrip() if k < len(right) else ""
            a = a if len(a) <= width else a[:width - 1] + "…"
            out.append(f"{a:<{width}} | {b}")
        out.append("")
    return out


def write_report(path, found: Flags) -> None:
    """A Markdown report for the teaching assistant: each flagged pair, its similarity, and the matching lines
    side by side; then what was not compared and why."""
    lines = [f"# Copy flags: {len(found.flags)} pair(s) at or above similarity {found.threshold:.2f}", "",
             "Scores are unchanged: a flag asks a person to read two pieces of code, it decides nothing. Similarity "
             "is the share of the shorter function found in the other in runs of at least "
             f"{RUN} tokens, after renaming every identifier and dropping comments, docstrings, layout and the "
             "exercise's own lines (course/grading/flags.py).", ""]
    for flag in found.flags:
        lines += [f"## Task {flag.task} {flag.name}: {flag.similarity:.2f}", "",
                  f"- left: {flag.left.who} ({flag.left.where})", f"- right: {flag.right.who} ({flag.right.where})",
                  "", "```"] + _side_by_side(flag) + ["```", ""]
    if found.worth_reading:
        lines += ["## Code worth reading", "",
                  "Lines that reach into the grader, patch modules, walk stack frames or start and signal processes. "
                  "None of it changes a score (the grader runs the checks in its own process); it shows what a "
                  "student tried.", ""]
        lines += [f"- {who} ({path}, cell {cell}): {why}: `{line[:100]}`"
                  for who, path, cell, line, why in found.worth_reading] + [""]
    lines += ["## Not compared", ""]
    for task_id, length in found.formulas.items():
        lines.append(f"- Task {task_id} {TASKS[task_id].name}: the course's own answer has {length} tokens, fewer "
                     f"than {FORMULA_TOKENS}: a formula that honest students write alike, not compared")
    for task_id, names in found.too_short.items():
        if task_id in found.formulas:
            continue
        if names:
            lines.append(f"- Task {task_id} {TASKS[task_id].name}: fewer than {MIN_TOKENS} tokens of their own, too "
                         f"short to tell copying from the one way to write it: {', '.join(names)}")
    for task_id, names in found.not_found.items():
        if names:
            lines.append(f"- Task {task_id} {TASKS[task_id].name}: no `def {TASKS[task_id].name}` in the notebook "
                         f"(defined another way, e.g. exec or an import, or its cell deleted): {', '.join(names)}")
    for task_id, references in found.references.items():
        if not references:
            lines.append(f"- Task {task_id} {TASKS[task_id].name}: no reference to compare with (students compared "
                         "with each other only)")
    lines += [f"- {note}" for note in found.notes]
    if lines[-1] == "":
        lines.append("Every function was compared.")
    Path(path).write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
