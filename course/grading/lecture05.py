"""The checks of lecture 5's graded tasks (antialiasing): 5.1 clip_polygon, 5.2 halfplane_pixel_area,
5.3 segment_pixels, 5.4 supersample, 5.5 convergence (an analysis: the fitted rate at which supersampling's
error falls on the grader's edges; its reference is ``_convergence`` here, there is no package function).

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.

Two tasks have package helpers that would do the whole job (``course.raster.pixel_triangle_pairs`` for
5.3; ``regular_offsets``, ``sample_fragments``, ``flat_colors`` and ``adaptive_supersample`` of
``course.antialias`` for 5.4): a function that reaches one of them scores 0 and is told so, as one that
reaches the task's reference does (``registry.calls_reference``, read from the code; nothing runs).
"""
from __future__ import annotations

import math

import torch

from .helpers import Fail, _call, _diagnose, _fmt, _ref, _shape, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


# ------------------------------------------------------------------------------- 5.1 clipping a polygon

def _walk(poly, line, inside, crossing, close: bool = True) -> torch.Tensor:
    """Sutherland–Hodgman with the rules given (float64): ``inside(s)`` decides a vertex, ``crossing(p, q, sp,
    sq)`` places an edge's crossing; ``close=False`` skips the closing edge. The reference's walk and the
    wrong answers of the typical mistakes."""
    s = poly[:, 0] * line[0] + poly[:, 1] * line[1] + line[2]
    n = poly.shape[0]
    out = []
    for k in range(n if close else n - 1):
        j = (k + 1) % n
        if inside(s[k]):
            out.append(poly[k])
        if inside(s[k]) != inside(s[j]):
            out.append(crossing(poly[k], poly[j], s[k], s[j]))
    return torch.stack(out) if out else poly.new_zeros((0, 2))


def _at(p, q, sp, sq):
    return p + sp / (sp - sq) * (q - p)                                   # where s reaches 0 along p → q


def _distinct(poly: torch.Tensor) -> torch.Tensor:
    """The polygon without repeated consecutive vertices (cyclically), float64: a vertex on the line makes
    the walk emit it twice (as a vertex and as a crossing), which is the same polygon."""
    p = poly.to(torch.float64)
    if p.shape[0] == 0:
        return p
    tol = 1e-6 * (1 + float(p.abs().max()))
    keep = []
    for v in p:
        if not keep or float((v - keep[-1]).abs().max()) > tol:
            keep.append(v)
    while len(keep) > 1 and float((keep[0] - keep[-1]).abs().max()) <= tol:
        keep.pop()
    return torch.stack(keep)


def _same_polygon(got: torch.Tensor, want: torch.Tensor, tol: float) -> bool:
    """The same region: equal distinct vertices in the same cyclic order, from any start vertex. Two answers
    with fewer than 3 distinct vertices (no area: a point, a segment or nothing) count as the same."""
    g, w = _distinct(got), _distinct(want)
    if g.shape[0] < 3 and w.shape[0] < 3:
        return True
    if g.shape != w.shape:
        return False
    scale = tol * (1 + float(w.abs().max()))
    return any(float((torch.roll(g, -k, 0) - w).abs().max()) <= scale for k in range(g.shape[0]))


def _clip_variants(poly, line) -> list:
    p, l = poly.to(torch.float64), line.to(torch.float64)
    keep = lambda s: bool(s >= 0)                                         # noqa: E731
    flipped = lambda p_, q, sp, sq: p_ + sq / (sq - sp) * (q - p_)        # noqa: E731
    s = p[:, 0] * l[0] + p[:, 1] * l[1] + l[2]
    return [(_walk(p, l, keep, _at, close=False), "the closing edge is missing: walk every edge, including the "
             "one from the last vertex back to the first"),
            (_walk(p, -l, keep, _at), "you kept the wrong side: keep the part where a x + b y + c >= 0"),
            (p[s >= 0], "the crossings are missing: where an edge p → q has its ends on different sides, add the "
             "point where it meets the line, p + s_p / (s_p - s_q) (q - p)"),
            (_walk(p, l, keep, flipped), "the crossing is measured from the wrong end: it lies at "
             "p + t (q - p) with t = s_p / (s_p - s_q), the fraction of the way from p where s reaches 0"),
            (_walk(p, l, keep, _at).flip(0), "the polygon runs the other way round: keep the input's order")]


def _clip_problem(got, poly, line, name, check_dtype) -> tuple[str | None, bool]:
    """(None, False) when ``got`` is the clipped polygon (any start vertex, repeats allowed), else what is wrong
    with it and whether that names the mistake (one typical mistake, and only one, gives this answer)."""
    expected = _ref("course.coverage", "clip_polygon")(poly, line)
    tol = 1e-9 if poly.dtype == torch.float64 else 1e-4
    try:
        g = to_tensor(got, name)
    except Fail as failure:
        return str(failure), True
    if g.dim() != 2 or g.shape[-1] != 2:
        if g.numel() == 0 and expected.shape[0] == 0:
            return f"{name}: nothing is left; return an empty (0, 2) tensor, got shape {_shape(g.shape)}", True
        return (f"{name}: return the clipped polygon as an (M, 2) tensor of vertices, got shape "
                f"{_shape(g.shape)}", True)
    if check_dtype and g.dtype != expected.dtype:
        return compare(g, expected, name=name, check_dtype=True), True
    s = poly[:, 0] * line[0] + poly[:, 1] * line[1] + line[2]
    if not torch.isfinite(g).all():
        hint = ("; a vertex lies exactly on the line (s = 0): compute a crossing only where the edge's ends lie "
                "on different sides, (s_p >= 0) != (s_q >= 0), so s_p - s_q is never 0") if (s == 0).any() else ""
        return f"{name}: NaN or inf in the polygon{hint}", bool(hint)
    if _same_polygon(g, expected, tol):
        return None, False
    explanations = {e for alternative, e in _clip_variants(poly, line)
                    if _same_polygon(g, alternative, 1e-4) and not _same_polygon(expected, alternative, 1e-4)}
    if len(explanations) == 1:
        return f"{name}: {explanations.pop()}", True
    n_in = int((s >= 0).sum())
    G, E = _distinct(g), _distinct(expected)
    if n_in == poly.shape[0] and G.shape[0] != E.shape[0]:
        return f"{name}: every vertex is inside (a x + b y + c >= 0): return the polygon as it is", True
    if n_in == 0:
        return f"{name}: every vertex is outside (a x + b y + c < 0): return an empty (0, 2) polygon", True
    if G.shape[0] != E.shape[0]:
        return (f"{name}: {E.shape[0]} distinct vertices expected (the vertices with a x + b y + c >= 0 and one "
                f"crossing for each edge whose ends lie on different sides), got {G.shape[0]}"), False
    best = min((torch.roll(G, -k, 0) for k in range(G.shape[0])), key=lambda r: float((r - E).abs().max()))
    return compare(best, E, name=name, check_dtype=False), False


def _first_problem(problems) -> str | None:
    """Of (message, names the mistake) pairs, the first that names the mistake, else the first message."""
    found = [(m, named) for m, named in problems if m]
    return next((m for m, named in found if named), found[0][0] if found else None)


def _convex(n: int, seed: int, dtype=torch.float32) -> torch.Tensor:
    """A seeded convex n-gon around a point near (4, 3), counter-clockwise on screen for even seeds."""
    g = generator(seed)
    angle = torch.sort(torch.rand(n, generator=g, dtype=torch.float64) * 2 * math.pi).values
    angle = angle + torch.arange(n, dtype=torch.float64) * 0.05                  # no two corners together
    radius = 1.5 + torch.rand(1, generator=g, dtype=torch.float64)
    centre = torch.tensor([4.0, 3.0], dtype=torch.float64) + torch.rand(2, generator=g, dtype=torch.float64)
    poly = centre + radius * torch.stack([angle.cos(), angle.sin()], -1)
    return (poly if seed % 2 else poly.flip(0)).to(dtype)


def _line_through(point, seed: int, dtype=torch.float32) -> torch.Tensor:
    """A line (a, b, c) through ``point`` in a seeded direction, with a seeded scale."""
    g = generator(seed)
    theta = float(torch.rand(1, generator=g, dtype=torch.float64)) * 2 * math.pi
    scale = 0.5 + 2 * float(torch.rand(1, generator=g, dtype=torch.float64))
    a, b = scale * math.cos(theta), scale * math.sin(theta)
    x, y = (float(v) for v in point)
    return torch.tensor([a, b, -(a * x + b * y)], dtype=torch.float64).to(dtype)


@task("5.1", "clip_polygon", points=3, reference=("course.coverage", "clip_polygon"))
def _check_clip_polygon(impl):
    def run(cases, check_dtype=False):
        problems = []
        for poly, line in cases:
            name = f"clip_polygon({len(poly)} vertices, line={_fmt(line)})"
            problems.append(_clip_problem(_call(impl, poly, line), poly, line, name, check_dtype))
        require(_first_problem(problems))

    def through():
        cases = []
        for k, n in enumerate((3, 4, 5, 6, 7, 8)):
            poly = _convex(n, 60 + k)
            p64 = poly.to(torch.float64)
            inner = p64.mean(0) + 0.4 * (p64[k % n] - p64.mean(0))                # a point inside
            cases.append((poly, _line_through(inner, 70 + k)))
        run(cases)

    def all_or_nothing():
        poly = _convex(5, 81)
        cases = [(poly, torch.tensor(line, dtype=torch.float32)) for line in (
            [1.0, 0.0, 0.0], [-1.0, 0.0, 20.0], [0.3, -1.0, -12.0], [-1.0, 0.0, -1.0])]   # all, all, none, none
        hexagon = _convex(6, 82).to(torch.float64)
        (x0, y0), (x1, y1) = hexagon[2].tolist(), hexagon.mean(0).tolist()   # through a vertex and the middle
        cases.append((hexagon.float(), torch.tensor([y0 - y1, x1 - x0, x0 * y1 - x1 * y0]).float()))
        run(cases)

    def stress():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        square = f64([[1.0, 1.0], [4.0, 1.0], [4.0, 4.0], [1.0, 4.0]])
        cases = [(square, f64(line)) for line in (
            [1.0, 0.0, -1.0],                                                 # an edge on the line, the rest in
            [-1.0, 1.0, 0.0],                                                 # the diagonal: two corners on it
            [0.0, -1.0, 2.5],                                                 # no vertex on it
            [-1.0, 0.0, 1.0], [-1.0, -1.0, 2.0],                              # an edge, a corner on it: no area
            [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0])]              # a = b = 0: all, all, nothing
        cases.append((f64([[0.0, 0.0], [1.0, 1.0], [3.0, 3.0]]), f64([1.0, 0.0, -0.5])))       # no area
        cases.append((f64([[2.0, 2.0], [2.0, 2.0], [5.0, 3.0], [3.0, 5.0]]), f64([1.0, -0.2, -2.5])))   # repeated
        far = _convex(7, 84, torch.float64) + 1e6
        cases.append((far, _line_through(far.mean(0), 85, torch.float64)))                     # far away
        cases.append((square, f64([1e-12, 2e-12, -6e-12])))                                    # tiny a, b, c
        run(cases, True)
    return grade_parts((1, "lines through convex polygons", through),
                       (1, "everything kept, nothing kept, a line through a vertex", all_or_nothing),
                       (1, "vertices on the line, a = b = 0, degenerate and far polygons, float64", stress))


# ---------------------------------------------------------------------- 5.2 a half-plane's pixel coverage

def _scalars(impl, cases, name) -> tuple[torch.Tensor, torch.dtype | None]:
    """The student's area for each (line, col, row), as an (N,) float64 tensor, and the dtype of the first
    result that was not the input's (None when all kept it)."""
    values, wrong_dtype = [], None
    for line, col, row in cases:
        out = _call(impl, line, col, row)
        if isinstance(out, (int, float)) and not isinstance(out, bool):
            values.append(float(out))
            continue
        t = to_tensor(out, name)
        if t.dim() != 0:
            raise Fail(f"{name}: return one number (a scalar tensor, shape ()), got shape {_shape(t.shape)}")
        if t.is_floating_point() and t.dtype != line.dtype and wrong_dtype is None:
            wrong_dtype = t.dtype
        values.append(float(t.reshape(())))
    return torch.tensor(values, dtype=torch.float64), wrong_dtype


def _area_variants(cases) -> list:
    ref = _ref("course.coverage", "halfplane_pixel_area")
    area = lambda fn: torch.stack([fn(l.to(torch.float64), c, r) for l, c, r in cases]).reshape(-1)  # noqa: E731
    centred = lambda l, c, r: ref(torch.stack([l[0], l[1], l[2] - 0.5 * l[0] - 0.5 * l[1]]), c, r)   # noqa: E731
    exact = area(ref)
    return [(1 - exact, "that is the other side: return the area where a x + b y + c >= 0"),
            (-exact, "the area came out negative: list the square's corners (0, 0), (1, 0), (1, 1), (0, 1) (they "
             "run clockwise on screen, y down, where the shoelace area is positive, as polygon_area's docstring "
             "says), or take the absolute value"),
            (area(lambda l, c, r: ref(l, 0, 0)), "the pixel's position is missing: pixel (row, col) is the square "
             "[col, col + 1] × [row, row + 1], not [0, 1] × [0, 1]"),
            (area(lambda l, c, r: ref(l, r, c)), "col and row are swapped: x runs along the columns (col), y "
             "along the rows (row)"),
            (area(centred), "pixel (row, col) is the square [col, col + 1] × [row, row + 1], centred at "
             "(col + 0.5, row + 0.5), not at (col, row)"),
            (area(lambda l, c, r: (l[0] * (c + 0.5) + l[1] * (r + 0.5) + l[2] >= 0).to(torch.float64)),
             "that is the point sample at the pixel's centre (0 or 1): return the covered area of the square, "
             "a fraction in [0, 1]")]


def _run_areas(impl, cases, name, check_dtype):
    ref = _ref("course.coverage", "halfplane_pixel_area")
    got, wrong_dtype = _scalars(impl, cases, name)
    expected = torch.stack([ref(l, c, r) for l, c, r in cases]).reshape(-1)
    if check_dtype and wrong_dtype is not None:
        require(f"{name}: dtype {str(expected.dtype).replace('torch.', '')} in, "
                f"{str(wrong_dtype).replace('torch.', '')} out (keep the input's dtype)")
    require(_diagnose(got, expected, name, _area_variants(cases)))


def _crossing_lines(n, seed, col, row, dtype=torch.float32) -> list:
    """n seeded lines through seeded points inside pixel (row, col)'s square."""
    g = generator(seed)
    points = torch.rand(n, 2, generator=g, dtype=torch.float64) * 0.8 + 0.1 + torch.tensor([col, row])
    return [_line_through(p, seed * 100 + k, dtype) for k, p in enumerate(points)]


@task("5.2", "halfplane_pixel_area", points=3, reference=("course.coverage", "halfplane_pixel_area"))
def _check_halfplane_pixel_area(impl):
    def through():
        cases = [(l, 5, 2) for l in _crossing_lines(12, 91, 5, 2)] + [(l, 1, 6) for l in _crossing_lines(8, 92, 1, 6)]
        _run_areas(impl, cases, "halfplane_pixel_area for lines through pixels (row 2, col 5) and (row 6, col 1)",
                   False)

    def borders():
        f32 = lambda v: torch.tensor(v, dtype=torch.float32)              # noqa: E731
        cases = [(f32([1.0, 0.0, -3.0]), 3, 4), (f32([1.0, 0.0, -4.0]), 3, 4),     # x >= 3, x >= 4: borders
                 (f32([0.0, -1.0, 5.0]), 3, 4), (f32([0.0, 1.0, -4.5]), 3, 4),     # y <= 5; y >= 4.5: a half
                 (f32([1.0, 1.0, -8.0]), 3, 4), (f32([-1.0, 1.0, 1.0]), 3, 4),     # diagonals through corners
                 (f32([1.0, 0.0, 2.0]), 3, 4), (f32([-2.0, -1.0, 1.0]), 3, 4),     # misses: all, nothing
                 (f32([0.7, -1.3, 0.2]), 0, 0), (f32([1.0, 2.0, -5.1]), 7, 0)]
        _run_areas(impl, cases, "halfplane_pixel_area for lines along pixel borders, through corners, missing the "
                   "pixel", False)
        far = [(line, 1000, 700) for line in _crossing_lines(6, 93, 1000, 700, torch.float64)]
        _run_areas(impl, far, "halfplane_pixel_area at pixel (row 700, col 1000), float64", False)

    def stress():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        cases = [(f64([0.0, 0.0, 1.0]), 2, 3), (f64([0.0, 0.0, 0.0]), 2, 3), (f64([0.0, 0.0, -1.0]), 2, 3),
                 (f64([3e8, -1e8, -7e8]), 2, 3), (f64([3e-9, -1e-9, -7e-9]), 2, 3),   # huge and tiny a, b, c
                 (f64([1.0, 1e-13, -2.25]), 2, 3), (f64([-1e-13, 1.0, -3.6]), 2, 3)]  # nearly axis-aligned
        cases += [(l, 9, 4) for l in _crossing_lines(6, 94, 9, 4, torch.float64)]
        _run_areas(impl, cases, "halfplane_pixel_area with a = b = 0, huge, tiny and axis-aligned lines, float64",
                   True)
    return grade_parts((1, "lines through the pixel", through),
                       (1, "pixel borders and corners, lines that miss, a far pixel", borders),
                       (1, "a = b = 0, huge and tiny coefficients, float64", stress))


# ------------------------------------------------------------------------ 5.3 the pixels a segment touches

def _segments(a, b) -> tuple[torch.Tensor, torch.Tensor]:
    return a.to(torch.float64).reshape(-1, 2), b.to(torch.float64).reshape(-1, 2)


def _centres(width, height) -> torch.Tensor:
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64),
                                indexing="ij")
    return torch.stack([cols + 0.5, rows + 0.5], -1)                       # (H, W, 2) as (x, y)


def _near_centres(a, b, width, height) -> torch.Tensor:
    """Pixels whose centre lies within half a pixel (Euclidean) of a segment: the centre-sampling mistake."""
    a, b = _segments(a, b)
    c = _centres(width, height)[..., None, :]                              # (H, W, 1, 2)
    d = b - a
    t = (((c - a) * d).sum(-1) / (d * d).sum(-1).clamp_min(1e-300)).clamp(0, 1)   # (H, W, N)
    return ((c - (a + t[..., None] * d)).norm(dim=-1) <= 0.5).any(-1)


def _stepped(a, b, width, height) -> torch.Tensor:
    """The pixels of points one pixel apart (or less) along each segment: a DDA line."""
    a, b = _segments(a, b)
    mask = torch.zeros(height, width, dtype=torch.bool)
    for p, q in zip(a, b):
        n = int(torch.ceil((q - p).abs().max()).clamp(max=1e5)) + 1
        pts = p + torch.linspace(0, 1, n, dtype=torch.float64)[:, None] * (q - p)
        col, row = pts[:, 0].floor().long(), pts[:, 1].floor().long()
        ok = (col >= 0) & (col < width) & (row >= 0) & (row < height)
        mask[row[ok], col[ok]] = True
    return mask


def _box(a, b, width, height) -> torch.Tensor:
    """The pixels whose closed squares meet the segments' bounding boxes."""
    a, b = _segments(a, b)
    c = _centres(width, height)[..., None, :]
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    return ((c + 0.5 >= lo) & (c - 0.5 <= hi)).all(-1).any(-1)


def _segment_variants(a, b, width, height) -> list:
    ref = _ref("course.antialias", "segment_pixels")
    a64, b64 = _segments(a, b)
    closed = ("a segment on a pixel border, or ending on one, touches the squares on both sides: squares are "
              "closed, [col, col + 1] × [row, row + 1], borders and corners included")
    variants = [(_near_centres(a, b, width, height), "you marked the pixels whose centre is near the segment: mark "
                 "every pixel whose square the segment touches (its supercover); a segment passing between two "
                 "rows of centres still crosses those pixels"),
                (_stepped(a, b, width, height), "you marked the pixels of points stepped along the segment (a DDA or "
                 "Bresenham line): it skips pixels the segment only clips at a corner; mark every pixel whose "
                 "closed square the segment touches"),
                (_box(a, b, width, height), "that is the segment's bounding box: mark only the pixels the segment "
                 "itself passes through"),
                (ref(a64.flip(-1), b64.flip(-1), width, height) if width == height else None,
                 "x and y are swapped: x = a[0] runs along the columns, y = a[1] along the rows (mask[row, col])")]
    for dx, dy in ((1e-7, 0.0), (-1e-7, 0.0), (0.0, 1e-7), (0.0, -1e-7), (1e-7, 1e-7), (-1e-7, -1e-7)):
        shift = torch.tensor([dx, dy], dtype=torch.float64)
        variants.append((ref(a64 + shift, b64 + shift, width, height), closed))
    return [(v, e) for v, e in variants if v is not None]


def _mask_problem(got, a, b, width, height, name) -> str | None:
    """None when ``got`` is the supercover mask, else what is wrong with it."""
    expected = _ref("course.antialias", "segment_pixels")(a, b, width, height)
    try:
        g = to_tensor(got, name)
    except Fail as failure:
        return str(failure)
    if g.shape != expected.shape:
        return compare(g, expected, name=name)
    if g.dtype != torch.bool:
        return f"{name}: return a bool mask (H, W), got dtype {str(g.dtype).replace('torch.', '')}"
    if torch.equal(g, expected):
        return None
    for alternative, explanation in _segment_variants(a, b, width, height):
        if torch.equal(g, alternative) and not torch.equal(expected, alternative):
            return f"{name}: {explanation}"
    missed, extra = expected & ~g, g & ~expected
    count = lambda m: f"{int(m.sum())} pixel{'s' if int(m.sum()) > 1 else ''}"   # noqa: E731
    if missed.any() and not extra.any():
        r, c = (int(i) for i in missed.nonzero()[0])
        return (f"{name}: {count(missed)} that the segment touches not marked (first: row {r}, col {c}); a pixel "
                "counts when the segment touches any point of its closed square, even a corner")
    if extra.any() and not missed.any():
        r, c = (int(i) for i in extra.nonzero()[0])
        return f"{name}: {count(extra)} that the segment does not touch marked (first: row {r}, col {c})"
    return compare(g, expected, name=name)


def _random_segments(n, seed, width, height):
    g = generator(seed)
    box = torch.tensor([width + 2.0, height + 2.0], dtype=torch.float64)
    a = torch.rand(n, 2, generator=g, dtype=torch.float64) * box - 1
    b = torch.rand(n, 2, generator=g, dtype=torch.float64) * box - 1
    return a, b


@task("5.3", "segment_pixels", points=3, reference=("course.antialias", "segment_pixels"))
def _check_segment_pixels(impl):
    W, H = 13, 9                                                           # not square: rows and columns differ

    def run(a, b, what, width=W, height=H):
        name = f"segment_pixels({_fmt(a)}, {_fmt(b)}, {width}, {height}) ({what})"
        require(_mask_problem(_call(impl, a, b, width, height), a, b, width, height, name))

    def single():
        a, b = _random_segments(8, 101, W, H)
        for p, q in zip(a, b):
            run(p, q, "one segment")

    def slivers_and_borders():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        run(f64([0.2, 2.6]), f64([12.8, 3.4]), "a shallow segment between two rows of pixel centres")
        run(f64([3.0, 1.5]), f64([3.0, 7.25]), "along the border x = 3")
        run(f64([2.2, 4.0]), f64([9.5, 4.0]), "along the border y = 4")
        run(f64([5.0, 5.0]), f64([8.5, 6.7]), "from a pixel corner")
        run(f64([1.0, 1.0]), f64([7.0, 7.0]), "through pixel corners")
        tri = f64([[1.3, 0.6], [11.7, 2.2], [4.1, 8.4]])
        run(tri, tri.roll(-1, 0), "a triangle's three edges at once, (3, 2)")

    def stress():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        run(f64([-6.0, 2.0]), f64([-1.5, 8.0]), "left of the image")
        run(f64([14.0, -3.0]), f64([20.0, 12.0]), "right of the image")
        run(f64([-5.0, -3.0]), f64([4.5, 6.2]), "starting outside the image")
        run(f64([4.3, 2.7]), f64([4.3, 2.7]), "zero length")
        run(f64([6.0, 3.0]), f64([6.0, 3.0]), "zero length, on a pixel corner")
        run(f64([0.0, 0.0]), f64([0.0, 0.0]), "zero length, at the image's corner")
        run(f64([-1e5, 2.31]), f64([1e5, 6.93]), "huge coordinates")
        run(torch.tensor([0.6, 7.7]), torch.tensor([12.2, 0.45]), "float32 input")
        run(f64([0.5, 0.5]), f64([4.5, 2.5]), "a 1 × 1 image", 1, 1)
    message = forbidden_call(impl, "segment_pixels", [("course.raster", "pixel_triangle_pairs")])
    if message:
        return 0, message
    return grade_parts((1, "random segments", single),
                       (1, "slivers, pixel borders and corners, several segments", slivers_and_borders),
                       (1, "outside the image, zero length, huge coordinates, float32", stress))


# ----------------------------------------------------------------------------------- 5.4 supersampling

def _screen_scene(tris, depths, width, height, dtype, Camera):
    """A mesh whose vertices are pixel positions (x, y) at the given depths, and an orthographic camera that
    maps world (x, y, z) to pixel (x, y) at depth z."""
    Mesh = _ref("course.mesh", "Mesh")
    tris = torch.as_tensor(tris, dtype=torch.float64)                      # (F, 3, 2)
    z = torch.as_tensor(depths, dtype=torch.float64)[:, None, None].expand(-1, 3, 1)
    verts = torch.cat([tris, z], -1).reshape(-1, 3).to(dtype)
    faces = torch.arange(verts.shape[0]).reshape(-1, 3)
    eye = torch.eye(3, dtype=dtype)
    return Mesh(verts, faces), Camera(eye, eye, torch.zeros(3, dtype=dtype), width, height, near=0.0, far=10.0,
                                      orthographic=True)


def _with_offsets(mesh, camera, colors, offsets, background, missed="background", divide="all"):
    """Supersampling with the sample offsets (S, 2) given and a rule for missed samples: the typical mistakes."""
    frags = _ref("course.raster", "rasterize")(mesh, camera, samples=offsets)
    face = frags.face_id                                                   # (H*W, S)
    bg = torch.as_tensor(background, dtype=torch.float64)
    c = colors.to(torch.float64)
    value = c[face]                                                        # -1 picks the last face
    if missed == "background":
        value = torch.where((face >= 0)[..., None], value, bg)
    elif missed == "black":
        value = torch.where((face >= 0)[..., None], value, torch.zeros(3, dtype=torch.float64))
    if divide == "hits":
        hits = (face >= 0).sum(1, keepdim=True)
        total = torch.where((face >= 0)[..., None], value, 0.0).sum(1)
        out = torch.where(hits > 0, total / hits.clamp_min(1), bg)
    else:
        out = value.mean(1)
    return out.view(camera.height, camera.width, 3)


def _grid(k, where="centre") -> torch.Tensor:
    a = torch.arange(k, dtype=torch.float64)
    if where == "corner":
        u = a / k
    elif where == "linspace":
        u = torch.linspace(0.0, 1.0, k, dtype=torch.float64) if k > 1 else torch.tensor([0.5], dtype=torch.float64)
    else:
        u = (a + 0.5) / k
    return torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(-1, 2)


def _supersample_variants(mesh, camera, colors, k, background) -> list:
    centre = _grid(k)
    v = lambda offsets, **kw: _with_offsets(mesh, camera, colors, offsets, background, **kw)   # noqa: E731
    return [(v(_grid(k, "corner")), "the samples sit at the cells' corners: sample (a, b) of a k × k grid lies at "
             "the centre of its cell, ((a + 0.5) / k, (b + 0.5) / k) from the pixel's top-left corner"),
            (v(_grid(k, "linspace")), "the samples are spread from 0 to 1 (linspace): the k × k samples sit at the "
             "centres of the grid's cells, ((a + 0.5) / k, (b + 0.5) / k); 0 and 1 are the pixel's borders"),
            (v(centre, missed="last"), "face_id -1 means no face there: a sample that hits nothing takes the "
             "background colour, not face_colors[-1] (the last face's)"),
            (v(centre, missed="black"), "a sample that hits nothing takes the background colour, not black"),
            (v(centre, divide="hits"), "divide by all k² samples (one that hits nothing counts with the background "
             "colour), not by the number of samples that hit a face"),
            (v(_grid(1)), "that is one sample per pixel: take k × k samples and average them")]


# Triangles in pixel coordinates (x right, y down), at depths: overlapping faces, one leaving the image, a
# sliver thinner than a pixel, edges at many slopes.
_SCENE_A = ([[[0.6, 0.4], [8.7, 1.9], [2.2, 6.5]], [[4.1, 0.2], [9.8, 5.6], [3.3, 6.8]],
             [[6.5, 3.1], [12.7, 4.4], [7.9, 9.3]]], [2.0, 1.0, 3.0])
_SCENE_B = ([[[-3.0, -2.0], [5.6, 0.7], [1.9, 7.4]], [[0.3, 5.2], [10.8, 6.1], [0.5, 5.45]],
             [[5.2, 1.1], [9.9, 0.3], [7.6, 4.8]], [[2.0, 2.0], [6.0, 2.0], [4.0, 5.0]]], [1.5, 0.5, 2.5, 1.0])


@task("5.4", "supersample", points=3, reference=("course.antialias", "supersample"))
def _check_supersample(impl):
    ref = _ref("course.antialias", "supersample")
    W, H = 11, 8                                                           # not square

    def run(scene, k, background, dtype, name, check_dtype=False):
        mesh, camera = _screen_scene(*scene, W, H, dtype, _ref("course.camera", "Camera"))
        colors = torch.rand(mesh.faces.shape[0], 3, generator=generator(110 + k), dtype=torch.float64).to(dtype)
        if background is None:
            got, bg = _call(impl, mesh, camera, colors, k), (0.0, 0.0, 0.0)
        else:
            got, bg = impl(mesh, camera, colors.clone(), k, background=background), background
        expected = ref(mesh, camera, colors, k, background=bg)
        require(_diagnose(got, expected, name, _supersample_variants(mesh, camera, colors, k, bg),
                          check_dtype=check_dtype))

    def basic():
        for k in (2, 4):
            run(_SCENE_A, k, None, torch.float32, f"supersample(three triangles, {W} × {H} pixels, k={k})")

    def background():
        for k in (3, 1):
            run(_SCENE_A, k, (0.1, 0.3, 0.6), torch.float32,
                f"supersample(three triangles, k={k}, background=(0.1, 0.3, 0.6))")

    def stress():
        run(_SCENE_B, 4, (0.9, 0.8, 0.2), torch.float64,
            "supersample(a sliver, a face leaving the image, overlapping faces, k=4), float64", True)
        off = ([[[20.0, 1.0], [30.0, 2.0], [25.0, 9.0]]], [1.0])
        run(off, 2, (0.25, 0.5, 0.75), torch.float64, "supersample(a face outside the image: all background)",
            True)
    message = forbidden_call(impl, "supersample", [("course.antialias", name) for name in (
        "regular_offsets", "sample_fragments", "flat_colors", "adaptive_supersample")])
    if message:
        return 0, message
    return grade_parts((1, "k = 2 and 4", basic), (1, "a background colour, k = 3 and 1", background),
                       (1, "slivers, faces leaving the image, float64", stress))


# ------------------------------------------------------------------- 5.5 how fast supersampling converges

def _exact_coverages(lines, width, height) -> torch.Tensor:
    """(L, H, W) float64: every pixel's coverage by each half-plane, ``course.coverage.halfplane_pixel_area``."""
    area = _ref("course.coverage", "halfplane_pixel_area")
    return torch.stack([torch.stack([torch.stack([area(line, c, r) for c in range(width)]) for r in range(height)])
                        for line in lines])


def _sampled_coverages(lines, width, height, k, jitter, seed, where="centre", pixel_index="row") -> torch.Tensor:
    """(L, H, W) float64: the fraction of each pixel's k × k samples with a x + b y + c >= 0; ``where`` and
    ``pixel_index`` give the typical mistakes (samples at the cells' corners; one pixel's jitter everywhere,
    ``"same"``; pixels numbered column-major, ``"col"``)."""
    P = width * height
    pixels = torch.arange(P)
    rows, cols = (pixels // width).to(torch.float64), (pixels % width).to(torch.float64)
    if jitter:
        index = {"row": pixels, "col": (pixels % width) * height + pixels // width, "same": torch.zeros_like(pixels)}
        offsets = _ref("course.antialias", "jittered_offsets")(k, index[pixel_index], seed)   # (P, S, 2)
    else:
        offsets = _grid(k, where).expand(P, -1, -1)                                           # (P, S, 2)
    x, y = cols[:, None] + offsets[..., 0], rows[:, None] + offsets[..., 1]                  # (P, S)
    a, b, c = (lines[:, i, None, None] for i in range(3))                                    # (L, 1, 1)
    return (a * x + b * y + c >= 0).to(torch.float64).mean(-1).reshape(-1, height, width)


def _slope(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """The least-squares slope of y against x."""
    return ((x - x.mean()) * (y - y.mean())).sum() / ((x - x.mean()) ** 2).sum()


def _convergence(lines, width, height, ks, jitter=False, seed=0, *, exact=None):
    """The reference of task 5.5: (errors (K,), exponent ()), both float64. errors[i] is the RMSE over all
    L · H · W pixels between k × k supersampled coverage (regular grid, or ``jittered_offsets`` of the flat
    pixel indices) and the exact coverage; the exponent is the least-squares slope of log(error) on log(k).
    ``exact``: the (L, H, W) exact coverages when already computed."""
    lines = torch.as_tensor(lines).to(torch.float64).reshape(-1, 3)
    exact = _exact_coverages(lines, width, height) if exact is None else exact
    errors = torch.stack([((_sampled_coverages(lines, width, height, k, jitter, seed) - exact) ** 2).mean().sqrt()
                          for k in ks])
    return errors, _slope(torch.log(torch.tensor(ks, dtype=torch.float64)), torch.log(errors))


def _convergence_variants(lines, width, height, ks, jitter, seed, exact) -> tuple[list, list]:
    """The typical mistakes' answers: (wrong errors, explanation) and (wrong exponent, explanation)."""
    lines = torch.as_tensor(lines).to(torch.float64).reshape(-1, 3)
    logk = torch.log(torch.tensor(ks, dtype=torch.float64))
    diffs = [_sampled_coverages(lines, width, height, k, jitter, seed) - exact for k in ks]
    errors = torch.stack([(d ** 2).mean().sqrt() for d in diffs])
    crossed = ((exact > 0) & (exact < 1)).to(torch.float64).mean().clamp_min(1e-12)
    wrong_errors = [
        (errors / crossed.sqrt(), "the RMSE is over every pixel of every image (L · height · width of them), not "
         "only over the pixels the edges cross"),
        (errors ** 2, "that is the mean squared error: take its square root (the RMSE)"),
        (torch.stack([d.abs().mean() for d in diffs]), "that is the mean absolute error: the task asks for the "
         "root of the mean squared error (RMSE)")]
    if jitter:
        for how, explanation in (("same", "every pixel has its own jittered samples: pass every pixel's flat index "
                                  "to antialias.jittered_offsets, not one pixel's samples for all"),
                                 ("col", "pixel (row, col) has the flat index row * width + col (row-major)")):
            wrong = [_sampled_coverages(lines, width, height, k, True, seed, pixel_index=how) - exact for k in ks]
            wrong_errors.append((torch.stack([(d ** 2).mean().sqrt() for d in wrong]), explanation))
    else:
        corner = [_sampled_coverages(lines, width, height, k, False, seed, where="corner") - exact for k in ks]
        wrong_errors.append((torch.stack([(d ** 2).mean().sqrt() for d in corner]), "the samples sit at the cells' "
                             "corners: sample (a, b) of the regular grid lies at ((a + 0.5) / k, (b + 0.5) / k)"))
    loge = torch.log(errors)
    p = _slope(logk, loge)
    wrong_exponents = [
        (-p, "the exponent is negative when the error falls as k grows: the slope of log(error) against log(k)"),
        (_slope(torch.tensor(ks, dtype=torch.float64), loge), "fit log(error) against log(k), not against k"),
        (_slope(loge, logk), "that is the slope of log(k) against log(error): fit log(error) = log(C) + p log(k), "
         "with the error on the vertical axis"),
        (_slope(logk, loge / math.log(10)), "use the same logarithm on both axes (natural or base 10)"),
        (_slope(logk / math.log(10), loge), "use the same logarithm on both axes (natural or base 10)"),
        (_slope(logk, 2 * loge), "that is the exponent of the mean squared error: fit the RMSE's logarithm")]
    return wrong_errors, wrong_exponents


def _run_convergence(impl, lines, width, height, ks, jitter, seed, what):
    name = f"convergence({what})"
    out = _call(impl, lines, width, height, list(ks), jitter, seed)
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise Fail(f"{name}: return a tuple (errors, exponent), got {type(out).__name__}")
    errors = to_tensor(out[0], f"{name} errors")
    try:
        exponent = torch.as_tensor(float(out[1]), dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise Fail(f"{name}: the exponent should be one number, got {type(out[1]).__name__}") from None
    exact = _exact_coverages(torch.as_tensor(lines).to(torch.float64).reshape(-1, 3), width, height)
    expected_errors, expected_exponent = _convergence(lines, width, height, ks, jitter, seed, exact=exact)
    wrong_errors, wrong_exponents = _convergence_variants(lines, width, height, ks, jitter, seed, exact)
    require(_diagnose(errors, expected_errors, f"{name} errors", wrong_errors, atol=1e-12, rtol=1e-6))
    require(_diagnose(exponent, expected_exponent, f"{name} exponent", wrong_exponents, atol=1e-6, rtol=1e-6))


def _lines(angles_deg, seed, width, height, dtype=torch.float64) -> torch.Tensor:
    """(L, 3) lines at the given angles (degrees from the x axis) through seeded points inside the image."""
    g = generator(seed)
    out = []
    for angle in angles_deg:
        x, y = (torch.rand(2, generator=g, dtype=torch.float64) * 0.6 + 0.2) * torch.tensor([width, height])
        a, b = -math.sin(math.radians(angle)), math.cos(math.radians(angle))      # the normal of the direction
        out.append([a, b, -(a * float(x) + b * float(y))])
    return torch.tensor(out, dtype=torch.float64).to(dtype)


@task("5.5", "convergence", points=4, reference=("course.grading.lecture05", "_convergence"))
def _check_convergence(impl):
    W, H = 12, 9                                                           # not square: rows and columns differ

    def generic():
        _run_convergence(impl, _lines([31.7, 58.3, 121.4, 147.9], 121, W, H), W, H, [1, 2, 4, 8, 16], False, 0,
                         "four edges at generic slopes, regular grid, k = 1 … 16")

    def near_axes():
        _run_convergence(impl, _lines([0.4, 89.3, 179.2, 270.6], 122, W, H), W, H, [2, 4, 8, 16], False, 0,
                         "four edges within a degree of an axis, regular grid, k = 2 … 16")

    def jittered():
        lines = _lines([12.5, 67.0, 103.3, 161.8, 45.5], 123, W, H)
        for seed in (0, 3):
            _run_convergence(impl, lines, W, H, [1, 2, 4, 8], True, seed, f"five edges, jitter=True, seed={seed}")

    def stress():
        _run_convergence(impl, _lines([23.0, 77.7], 124, W, H, torch.float32), W, H, [3, 5, 7, 12], False, 0,
                         "k not powers of two, float32 lines")
        _run_convergence(impl, _lines([38.2], 125, 7, 5), 7, 5, [1, 3, 9], True, 7, "one edge, 7 × 5 pixels, jitter")
    return grade_parts((1, "edges at generic slopes", generic), (1, "edges near the axes", near_axes),
                       (1, "stratified jitter", jittered), (1, "other k, float32, one edge", stress))
