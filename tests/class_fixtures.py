"""Answers and notebooks of a small made-up class, for the copy-flag, gradebook and Gradescope tests.

``HONEST`` holds two correct solutions of four tasks, written independently and differently (a textbook loop
against a vectorised form, a linear solve against Cramer's rule, ...): copy flags must not flag them.
``pasted_reference`` is what a student who pastes the package's code does: the reference function's source
with its docstring and comments gone, every local name renamed and the function renamed to the task's; copy
flags must flag it. ``exercise_with`` writes such answers into a copy of the released exercise, as a student
would hand it in.
"""
from __future__ import annotations

import ast
import importlib
import inspect
import textwrap
from pathlib import Path

import nbformat

from course.grading import TASKS

ROOT = Path(__file__).resolve().parent.parent

HONEST = {
    "1.1": ['''def rodrigues(axis_angle):
    angle = torch.sqrt((axis_angle ** 2).sum())
    identity = torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device)
    if angle.item() < 1e-12:
        return identity
    k = axis_angle / angle
    skew = torch.zeros(3, 3, dtype=axis_angle.dtype, device=axis_angle.device)
    skew[0, 1], skew[0, 2] = -k[2], k[1]
    skew[1, 0], skew[1, 2] = k[2], -k[0]
    skew[2, 0], skew[2, 1] = -k[1], k[0]
    return identity + torch.sin(angle) * skew + (1.0 - torch.cos(angle)) * torch.matmul(skew, skew)
''', '''def rodrigues(axis_angle):
    w = axis_angle
    theta = w.norm()
    I = torch.eye(3, dtype=w.dtype, device=w.device)
    if theta <= 1e-12:
        return I
    k = w / theta
    cross_matrix = torch.linalg.cross(k.expand(3, 3), I).T      # column i is k x e_i
    c, s = torch.cos(theta), torch.sin(theta)
    return c * I + s * cross_matrix + (1 - c) * torch.outer(k, k)
'''],
    "1.2": ['''def look_at(eye, target, up):
    f = target - eye
    f = f / f.norm()
    s = torch.cross(f, up, dim=0)
    s = s / s.norm()
    d = torch.cross(f, s, dim=0)
    R = torch.stack((s, d, f), dim=0)
    t = -(R @ eye)
    return R, t
''', '''def look_at(eye, target, up):
    normalize = torch.nn.functional.normalize
    forward = normalize(target - eye, dim=0)
    right = normalize(torch.linalg.cross(forward, up), dim=0)
    down = torch.linalg.cross(forward, right)
    rotation = torch.empty(3, 3, dtype=eye.dtype, device=eye.device)
    rotation[0], rotation[1], rotation[2] = right, down, forward
    translation = -torch.mv(rotation, eye)
    return rotation, translation
'''],
    "3.2": ['''def barycentric(tri, points):
    tri = torch.as_tensor(tri)
    points = torch.as_tensor(points, dtype=tri.dtype)
    a, b, c = tri[0], tri[1], tri[2]
    ab, ac = b - a, c - a
    det = ab[0] * ac[1] - ab[1] * ac[0]
    if det == 0:
        return torch.full((points.shape[0], 3), 1.0 / 3.0, dtype=tri.dtype)
    ap = points - a
    beta = (ap[:, 0] * ac[1] - ap[:, 1] * ac[0]) / det
    gamma = (ab[0] * ap[:, 1] - ab[1] * ap[:, 0]) / det
    return torch.stack([1 - beta - gamma, beta, gamma], dim=1)
''', '''def barycentric(tri, points):
    tri = torch.as_tensor(tri)
    points = torch.as_tensor(points, dtype=tri.dtype)
    weights = []
    for k in range(3):
        d1 = tri[(k + 1) % 3] - points
        d2 = tri[(k + 2) % 3] - points
        weights.append(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    area = e1[0] * e2[1] - e1[1] * e2[0]
    w = torch.stack(weights, dim=1)
    if area == 0:
        return torch.ones_like(w) / 3
    return w / area
'''],
    "7.1": ['''def ray_triangle(origins, directions, tris):
    a, b, c = tris.unbind(1)
    edge1, edge2 = b - a, c - a
    pvec = torch.cross(directions, edge2, dim=-1)
    det = torch.einsum("ij,ij->i", edge1, pvec)
    ok = det != 0
    inv = 1.0 / torch.where(ok, det, torch.ones_like(det))
    tvec = origins - a
    u = torch.einsum("ij,ij->i", tvec, pvec) * inv
    qvec = torch.cross(tvec, edge1, dim=-1)
    v = torch.einsum("ij,ij->i", directions, qvec) * inv
    dist = torch.einsum("ij,ij->i", edge2, qvec) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0)
    inf = torch.full_like(dist, float("inf"))
    return torch.where(hit, dist, inf), hit
''', '''def ray_triangle(origins, directions, tris):
    n = origins.shape[0]
    v0 = tris[:, 0, :]
    system = torch.stack([-directions, tris[:, 1, :] - v0, tris[:, 2, :] - v0], dim=2)   # (N, 3, 3)
    rhs = origins - v0
    singular = torch.linalg.det(system) == 0
    eye = torch.eye(3, dtype=system.dtype).expand(n, 3, 3)
    safe_system = torch.where(singular[:, None, None], eye, system)
    tuv = torch.linalg.solve(safe_system, rhs.unsqueeze(2)).squeeze(2)
    t, u, v = tuv[:, 0], tuv[:, 1], tuv[:, 2]
    inside = (u >= 0) & (v >= 0) & (u + v <= 1)
    hit = ~singular & inside & (t > 0)
    return torch.where(hit, t, torch.full_like(t, math.inf)), hit
'''],
}


class _Rename(ast.NodeTransformer):
    def __init__(self, names: dict[str, str]):
        self.names = names

    def visit_Name(self, node):
        node.id = self.names.get(node.id, node.id)
        return node

    def visit_arg(self, node):
        node.arg = self.names.get(node.arg, node.arg)
        return node


def rename_locals(source: str, name: str | None = None, prefix: str = "my_") -> str:
    """``source`` (one function) with every argument and local variable renamed, its docstring and comments
    dropped and its layout redone (``ast.unparse``), and the function renamed to ``name``."""
    tree = ast.parse(textwrap.dedent(source))
    fn = tree.body[0]
    fn.name = name or fn.name
    if isinstance(fn.body[0], ast.Expr) and isinstance(fn.body[0].value, ast.Constant) and len(fn.body) > 1:
        fn.body = fn.body[1:]
    local = {a.arg for a in ast.walk(fn) if isinstance(a, ast.arg)}
    local |= {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
    return ast.unparse(_Rename({n: f"{prefix}{n}_{k}" for k, n in enumerate(sorted(local))}).visit(tree)) + "\n"


def parenthesise(source: str) -> str:
    """``source`` with every operand of every operator, comparison and call wrapped in parentheses of its own: the
    same program, written to defeat a comparison of tokens (``(a) - (b)`` for ``a - b``)."""
    lines = source.splitlines(keepends=True)
    starts = [0]
    for line in lines:
        starts.append(starts[-1] + len(line))
    spans = []
    for node in ast.walk(ast.parse(source)):
        operands = {ast.BinOp: lambda n: [n.left, n.right], ast.Compare: lambda n: [n.left, *n.comparators],
                    ast.UnaryOp: lambda n: [n.operand], ast.Call: lambda n: list(n.args)}.get(type(node))
        for o in operands(node) if operands else []:
            spans.append((starts[o.lineno - 1] + o.col_offset, starts[o.end_lineno - 1] + o.end_col_offset))
    marks = sorted([(end, 0, ")") for _, end in spans] + [(start, 1, "(") for start, _ in spans], reverse=True)
    for position, _, mark in marks:                                    # from the end: earlier offsets stay
        source = source[:position] + mark + source[position:]
    ast.parse(source)
    return source


def reference_source(task_id: str) -> str:
    """The source of the package function task ``task_id`` re-implements."""
    module, qualname = TASKS[task_id].reference
    value = importlib.import_module(module)
    for part in qualname.split("."):
        value = getattr(value, part)
    return inspect.getsource(value)


def pasted_reference(task_id: str) -> str:
    """The reference pasted as the task's function, with renamed variables and no docstring or comments."""
    return rename_locals(reference_source(task_id), TASKS[task_id].name)


def exercise_with(lecture_file: str, answers: dict[str, str], extra_cells=()) -> nbformat.NotebookNode:
    """The released exercise ``exercises/<lecture_file>`` with the cell defining each function of ``answers``
    (function name -> source) replaced by that source, and ``extra_cells`` (sources) appended."""
    nb = nbformat.read(str(ROOT / "exercises" / lecture_file), as_version=4)
    for cell in nb.cells:
        for name, source in answers.items():
            if cell.cell_type == "code" and f"def {name}(" in cell.source:
                cell.source = source
    for source in extra_cells:
        nb.cells.append(nbformat.v4.new_code_cell(source))
    return nb


def write(nb, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, str(path))
    return path
