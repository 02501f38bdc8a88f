"""Lecture 05's graded tasks (course/grading/lecture05.py): the references score full marks, a solution written
as a student would scores full marks without calling them, typical mistakes lose points with the diagnosis a
student can act on, and a function that calls a package helper doing the task's work scores 0 and is told so."""
import pytest
import torch

from course import antialias, coverage, raster
from course.grading import TASKS, run_check, tasks_for_lecture
from course.grading.lecture05 import _convergence
from grading_contract import contract

REFERENCES = {
    "5.1": coverage.clip_polygon,
    "5.2": coverage.halfplane_pixel_area,
    "5.3": antialias.segment_pixels,
    "5.4": antialias.supersample,
    "5.5": _convergence,
}


# ------------------------------------------------------------------------------ solutions, as students write

def clip_polygon(poly, line):
    s = poly @ line[:2] + line[2]                                          # (N,) signed value per vertex
    inside = s >= 0
    out = []
    for k in range(poly.shape[0]):
        j = (k + 1) % poly.shape[0]
        if inside[k]:
            out.append(poly[k])
        if inside[k] != inside[j]:
            out.append(poly[k] + s[k] / (s[k] - s[j]) * (poly[j] - poly[k]))
    return torch.stack(out) if out else poly.new_zeros((0, 2))


def shoelace(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * (x * y.roll(-1) - x.roll(-1) * y).sum()


def halfplane_pixel_area(line, col, row):
    a, b, c = line
    local = torch.stack([a, b, c + a * col + b * row])                     # pixel-relative
    square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=line.dtype)
    return shoelace(clip_polygon(square, local))


def segment_pixels(a, b, width, height):
    a = torch.as_tensor(a, dtype=torch.float64).reshape(-1, 2)
    b = torch.as_tensor(b, dtype=torch.float64).reshape(-1, 2)
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64),
                                indexing="ij")
    x0, y0 = cols[..., None], rows[..., None]                              # (H, W, 1) top-left corners
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    overlap = (lo[:, 0] <= x0 + 1) & (hi[:, 0] >= x0) & (lo[:, 1] <= y0 + 1) & (hi[:, 1] >= y0)
    d = b - a
    offset = (x0 + 0.5 - a[:, 0]) * -d[:, 1] + (y0 + 0.5 - a[:, 1]) * d[:, 0]
    return (overlap & (offset.abs() <= 0.5 * (d[:, 0].abs() + d[:, 1].abs()))).any(-1)


def supersample(mesh, camera, face_colors, k, background=(0.0, 0.0, 0.0)):
    background = torch.as_tensor(background, dtype=face_colors.dtype)
    u = (torch.arange(k, dtype=torch.float64) + 0.5) / k
    offsets = torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(-1, 2)
    face = raster.rasterize(mesh, camera, samples=offsets).face_id         # (H*W, k²)
    color = torch.where((face >= 0)[..., None], face_colors[face.clamp_min(0)], background)
    return color.mean(1).view(camera.height, camera.width, 3)


def convergence(lines, width, height, ks, jitter=False, seed=0):
    lines = torch.as_tensor(lines, dtype=torch.float64).reshape(-1, 3)
    exact = torch.stack([torch.stack([torch.stack([halfplane_pixel_area(line, c, r) for c in range(width)])
                                      for r in range(height)]) for line in lines])   # (L, H, W)
    pixels = torch.arange(width * height)
    row, col = (pixels // width).double(), (pixels % width).double()
    errors = []
    for k in ks:
        if jitter:
            offsets = antialias.jittered_offsets(k, pixels, seed)             # (P, k², 2)
        else:
            u = (torch.arange(k, dtype=torch.float64) + 0.5) / k
            offsets = torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(1, -1, 2)
        x, y = col[:, None] + offsets[..., 0], row[:, None] + offsets[..., 1]
        s = lines[:, 0, None, None] * x + lines[:, 1, None, None] * y + lines[:, 2, None, None]
        errors.append((((s >= 0).double().mean(-1).reshape(-1, height, width) - exact) ** 2).mean().sqrt())
    errors = torch.stack(errors)
    x, y = torch.log(torch.tensor(ks, dtype=torch.float64)), torch.log(errors)
    return errors, float(((x - x.mean()) * (y - y.mean())).sum() / ((x - x.mean()) ** 2).sum())


SOLUTIONS = {"5.1": clip_polygon, "5.2": halfplane_pixel_area, "5.3": segment_pixels, "5.4": supersample,
             "5.5": convergence}


# ------------------------------------------------------------------------------------------ mistakes

def clip_with(inside=lambda s: s >= 0, crossing=None, close=True, empty=None):
    def clip_polygon(poly, line):
        s = poly @ line[:2] + line[2]
        out, n = [], poly.shape[0]
        for k in range(n if close else n - 1):
            j = (k + 1) % n
            if inside(s[k]):
                out.append(poly[k])
            if crossing is None and inside(s[k]) != inside(s[j]):
                out.append(poly[k] + s[k] / (s[k] - s[j]) * (poly[j] - poly[k]))
            elif crossing == "flipped" and inside(s[k]) != inside(s[j]):
                out.append(poly[k] + s[j] / (s[j] - s[k]) * (poly[j] - poly[k]))
            elif crossing == "product" and s[k] * s[j] <= 0 and not (inside(s[k]) and inside(s[j]) and
                                                                     s[k] != 0 and s[j] != 0):
                out.append(poly[k] + s[k] / (s[k] - s[j]) * (poly[j] - poly[k]))
        if not out:
            return poly.new_zeros((0, 2)) if empty is None else empty
        return torch.stack(out)
    return clip_polygon


def area_with(fn):
    return lambda line, col, row: fn(line.double(), col, row).to(line.dtype)


A = coverage.halfplane_pixel_area


def segment_near_centres(a, b, width, height):
    a = torch.as_tensor(a, dtype=torch.float64).reshape(-1, 2)
    b = torch.as_tensor(b, dtype=torch.float64).reshape(-1, 2)
    rows, cols = torch.meshgrid(torch.arange(height) + 0.5, torch.arange(width) + 0.5, indexing="ij")
    c = torch.stack([cols, rows], -1).double()[..., None, :]              # (H, W, 1, 2) centres
    d = b - a
    t = (((c - a) * d).sum(-1) / (d * d).sum(-1).clamp_min(1e-300)).clamp(0, 1)
    return ((c - (a + t[..., None] * d)).norm(dim=-1) <= 0.5).any(-1)


def segment_dda(a, b, width, height):
    mask = torch.zeros(height, width, dtype=torch.bool)
    a, b = torch.as_tensor(a, dtype=torch.float64), torch.as_tensor(b, dtype=torch.float64)
    for p, q in zip(a.reshape(-1, 2), b.reshape(-1, 2)):
        n = int((q - p).abs().max().ceil().clamp(max=1e5)) + 1
        pts = p + torch.linspace(0, 1, n, dtype=torch.float64)[:, None] * (q - p)
        col, row = pts[:, 0].floor().long(), pts[:, 1].floor().long()
        ok = (col >= 0) & (col < width) & (row >= 0) & (row < height)
        mask[row[ok], col[ok]] = True
    return mask


def segment_open_squares(a, b, width, height):
    a = torch.as_tensor(a, dtype=torch.float64).reshape(-1, 2)
    b = torch.as_tensor(b, dtype=torch.float64).reshape(-1, 2)
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64),
                                indexing="ij")
    x0, y0 = cols[..., None], rows[..., None]
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    overlap = (lo[:, 0] < x0 + 1) & (hi[:, 0] > x0) & (lo[:, 1] < y0 + 1) & (hi[:, 1] > y0)
    d = b - a
    offset = (x0 + 0.5 - a[:, 0]) * -d[:, 1] + (y0 + 0.5 - a[:, 1]) * d[:, 0]
    return (overlap & (offset.abs() < 0.5 * (d[:, 0].abs() + d[:, 1].abs()))).any(-1)


def segment_box(a, b, width, height):
    a = torch.as_tensor(a, dtype=torch.float64).reshape(-1, 2)
    b = torch.as_tensor(b, dtype=torch.float64).reshape(-1, 2)
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float64), torch.arange(width, dtype=torch.float64),
                                indexing="ij")
    x0, y0 = cols[..., None], rows[..., None]
    lo, hi = torch.minimum(a, b), torch.maximum(a, b)
    return ((lo[:, 0] <= x0 + 1) & (hi[:, 0] >= x0) & (lo[:, 1] <= y0 + 1) & (hi[:, 1] >= y0)).any(-1)


def segment_via_pairs(a, b, width, height):
    tri = torch.stack([torch.as_tensor(a), torch.as_tensor(b), torch.as_tensor(b)]).reshape(3, -1, 2).transpose(0, 1)
    pixel, _ = raster.pixel_triangle_pairs(tri, width, height)
    return torch.zeros(height * width, dtype=torch.bool).index_fill(0, pixel, True).view(height, width)


def supersample_with(where="centre", missed="background", divide="all", one_sample=False):
    def supersample(mesh, camera, face_colors, k, background=(0.0, 0.0, 0.0)):
        background = torch.as_tensor(background, dtype=face_colors.dtype)
        a = torch.arange(k, dtype=torch.float64)
        u = {"centre": (a + 0.5) / k, "corner": a / k,
             "linspace": torch.linspace(0, 1, k, dtype=torch.float64) if k > 1 else a + 0.5}[where]
        offsets = torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(-1, 2)
        if one_sample:
            offsets = torch.tensor([[0.5, 0.5]])
        face = raster.rasterize(mesh, camera, samples=offsets).face_id
        hit = (face >= 0)[..., None]
        color = face_colors[face]                                          # -1: the last face's colour
        if missed == "background":
            color = torch.where(hit, color, background)
        elif missed == "black":
            color = torch.where(hit, color, torch.zeros_like(background))
        if divide == "hits":
            n = hit.sum(1)
            color = torch.where(n > 0, torch.where(hit, color, 0).sum(1) / n.clamp_min(1), background)
        else:
            color = color.mean(1)
        return color.view(camera.height, camera.width, 3)
    return supersample


def supersample_via_offsets(mesh, camera, face_colors, k, background=(0.0, 0.0, 0.0)):
    background = torch.as_tensor(background, dtype=face_colors.dtype)
    face = raster.rasterize(mesh, camera, samples=antialias.regular_offsets(k)).face_id
    color = torch.where((face >= 0)[..., None], face_colors[face.clamp_min(0)], background)
    return color.mean(1).view(camera.height, camera.width, 3)


def convergence_with(errors=None, exponent=None):
    """The reference with one step changed: errors(lines, w, h, ks, jitter, seed, errors) and exponent(ks, errors)."""
    def convergence(lines, width, height, ks, jitter=False, seed=0):
        e, p = _convergence(lines, width, height, ks, jitter, seed)
        e = e if errors is None else errors(lines, width, height, ks, jitter, seed, e)
        if exponent is not None:
            p = exponent(torch.tensor(ks, dtype=torch.float64), e)
        return e, p
    return convergence


def slope(x, y):
    return float(((x - x.mean()) * (y - y.mean())).sum() / ((x - x.mean()) ** 2).sum())


def jitter_for_one_pixel(lines, width, height, ks, jitter, seed, e):
    if not jitter:
        return e
    from course.grading.lecture05 import _exact_coverages, _sampled_coverages
    lines = torch.as_tensor(lines).double().reshape(-1, 3)
    exact = _exact_coverages(lines, width, height)
    return torch.stack([((_sampled_coverages(lines, width, height, k, True, seed, pixel_index="same") - exact) ** 2)
                        .mean().sqrt() for k in ks])


def corners_not_centres(lines, width, height, ks, jitter, seed, e):
    if jitter:
        return e
    from course.grading.lecture05 import _exact_coverages, _sampled_coverages
    lines = torch.as_tensor(lines).double().reshape(-1, 3)
    exact = _exact_coverages(lines, width, height)
    return torch.stack([((_sampled_coverages(lines, width, height, k, False, seed, where="corner") - exact) ** 2)
                        .mean().sqrt() for k in ks])


MISTAKES = [
    ("5.1", lambda poly, line: coverage.clip_polygon(poly, -line), 0, ["you kept the wrong side"]),
    ("5.1", lambda poly, line: poly[poly @ line[:2] + line[2] >= 0], 0, ["the crossings are missing"]),
    ("5.1", clip_with(crossing="flipped"), 0, ["measured from the wrong end", "s_p / (s_p - s_q)"]),
    ("5.1", clip_with(close=False), 0, ["closing edge is missing"]),
    ("5.1", lambda poly, line: coverage.clip_polygon(poly, line).flip(0), 0, ["the other way round"]),
    ("5.1", clip_with(crossing="product"), 2, ["NaN", "exactly on the line", "(s_p >= 0) != (s_q >= 0)"]),
    ("5.1", clip_with(empty=torch.zeros(0)), 1, ["return an empty (0, 2) tensor, got shape (0,)"]),
    ("5.1", lambda poly, line: coverage.clip_polygon(poly, line).float(), 2, ["dtype float64 in, float32 out"]),
    ("5.1", lambda poly, line: list(coverage.clip_polygon(poly, line)), 0, ["stack it into one tensor"]),
    ("5.2", area_with(lambda l, c, r: 1 - A(l, c, r)), 0, ["the other side"]),
    ("5.2", area_with(lambda l, c, r: -A(l, c, r)), 0, ["came out negative", "(0, 0), (1, 0), (1, 1), (0, 1)"]),
    ("5.2", area_with(lambda l, c, r: A(l, 0, 0)), 0, ["the pixel's position is missing"]),
    ("5.2", area_with(lambda l, c, r: A(l, r, c)), 0, ["col and row are swapped"]),
    ("5.2", area_with(lambda l, c, r: A(torch.stack([l[0], l[1], l[2] - 0.5 * l[0] - 0.5 * l[1]]), c, r)), 0,
     ["centred at (col + 0.5, row + 0.5)"]),
    ("5.2", area_with(lambda l, c, r: (l[0] * (c + 0.5) + l[1] * (r + 0.5) + l[2] >= 0).double()), 0,
     ["point sample at the pixel's centre"]),
    ("5.2", lambda line, col, row: A(line, col, row).float(), 1, ["dtype float64 in, float32 out",
                                                                   "(float64 in: compute in float64)"]),
    ("5.2", lambda line, col, row: A(line, col, row)[None], 0, ["return one number", "got shape (1,)"]),
    ("5.3", segment_near_centres, 0, ["whose centre is near the segment", "supercover"]),
    ("5.3", segment_dda, 0, ["stepped along the segment"]),
    ("5.3", segment_box, 0, ["the segment's bounding box"]),
    ("5.3", segment_open_squares, 1, ["that the segment touches not marked", "closed square"]),
    ("5.3", lambda a, b, w, h: antialias.segment_pixels(a, b, w, h).float(), 0, ["return a bool mask"]),
    ("5.3", lambda a, b, w, h: antialias.segment_pixels(a, b, w, h).T, 0, ["shape (9, 13) expected, got (13, 9)"]),
    ("5.4", supersample_with(where="corner"), 0, ["cells' corners", "(a + 0.5) / k"]),
    ("5.4", supersample_with(where="linspace"), 0, ["linspace"]),
    ("5.4", supersample_with(missed="last"), 0, ["face_id -1 means no face there", "not face_colors[-1]"]),
    ("5.4", supersample_with(missed="black"), 1, ["takes the background colour, not black"]),
    ("5.4", supersample_with(divide="hits"), 0, ["divide by all k² samples"]),
    ("5.4", supersample_with(one_sample=True), 0, ["one sample per pixel"]),
    ("5.4", lambda m, c, f, k, background=(0.0, 0.0, 0.0): antialias.supersample(m, c, f, k).transpose(0, 1), 0,
     ["shape (8, 11, 3) expected, got (11, 8, 3)"]),
    ("5.5", convergence_with(errors=lambda *args: args[-1] ** 2), 0, ["mean squared error", "square root"]),
    ("5.5", convergence_with(exponent=lambda ks, e: -slope(ks.log(), e.log())), 0, ["exponent is negative"]),
    ("5.5", convergence_with(exponent=lambda ks, e: slope(ks, e.log())), 0, ["against log(k), not against k"]),
    ("5.5", convergence_with(exponent=lambda ks, e: slope(e.log(), ks.log())), 0, ["slope of log(k) against"]),
    ("5.5", convergence_with(exponent=lambda ks, e: slope(ks.log(), e.log10())), 0, ["same logarithm"]),
    ("5.5", convergence_with(errors=corners_not_centres), 1, ["cells' corners", "(a + 0.5) / k"]),
    ("5.5", convergence_with(errors=jitter_for_one_pixel), 2, ["its own jittered samples"]),
    ("5.5", lambda lines, width, height, ks, jitter=False, seed=0: _convergence(lines, width, height, ks, jitter,
                                                                                 seed)[1], 0,
     ["return a tuple (errors, exponent)"]),
]


def test_lecture_05_has_four_tasks_of_three_points_and_an_analysis_of_four():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(5)] == [
        ("5.1", "clip_polygon", 3), ("5.2", "halfplane_pixel_area", 3), ("5.3", "segment_pixels", 3),
        ("5.4", "supersample", 3), ("5.5", "convergence", 4)]
    assert {t.id: t.reference for t in tasks_for_lecture(5)} == {
        "5.1": ("course.coverage", "clip_polygon"), "5.2": ("course.coverage", "halfplane_pixel_area"),
        "5.3": ("course.antialias", "segment_pixels"), "5.4": ("course.antialias", "supersample"),
        "5.5": ("course.grading.lecture05", "_convergence")}
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)               # a mistake for every task


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


@pytest.mark.parametrize("task_id, impl, name", [
    ("5.3", segment_via_pairs, "course.raster.pixel_triangle_pairs"),
    ("5.4", supersample_via_offsets, "course.antialias.regular_offsets"),
    ("5.4", lambda m, c, f, k, background=(0.0, 0.0, 0.0): antialias.adaptive_supersample(m, c, f, k)[0],
     "course.antialias.adaptive_supersample")])
def test_a_helper_that_does_the_tasks_work_scores_zero(task_id, impl, name):
    result = run_check(task_id, impl)
    assert result.points == 0
    assert result.message.startswith(f"{TASKS[task_id].name} calls {name}, which does this task's work for you")


CALLING_THE_REFERENCE = {
    "5.1": lambda poly, line: coverage.clip_polygon(poly, line),
    "5.2": lambda line, col, row: coverage.halfplane_pixel_area(line, col, row),
    "5.3": lambda a, b, width, height: antialias.segment_pixels(a, b, width, height),
    "5.4": lambda mesh, camera, face_colors, k: antialias.supersample(mesh, camera, face_colors, k),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_REFERENCE))
def test_calling_the_reference_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_REFERENCE[task_id])
    assert result.points == 0 and "the package function this task re-implements" in result.message


def test_a_segment_touches_the_closed_squares_around_a_corner():
    """The reference's supercover: a segment from a pixel corner marks the four pixels that share it."""
    mask = antialias.segment_pixels(torch.tensor([2.0, 2.0]), torch.tensor([2.0, 2.0]), 4, 4)
    assert mask.nonzero().tolist() == [[1, 1], [1, 2], [2, 1], [2, 2]]


SUPERSAMPLE_SOURCE = '''
def supersample(mesh, camera, face_colors, k, background=(0.0, 0.0, 0.0)):
    background = torch.as_tensor(background, dtype=face_colors.dtype)
    u = (torch.arange(k, dtype=torch.float64) + 0.5) / k
    offsets = torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(-1, 2)
    face = raster.rasterize(mesh, camera, samples=offsets).face_id
    color = torch.where((face >= 0)[..., None], face_colors[face.clamp_min(0)], background)
    return color.mean(1).view(camera.height, camera.width, 3)
'''


def test_the_cameras_of_the_check_pass_the_students_copy_of_the_package(monkeypatch):
    """The grader imports course afresh before it runs the checks, while the notebook's functions keep the
    modules they imported: their rasterize tests isinstance(camera, Camera) against their own Camera class."""
    import importlib
    import sys
    saved = {name for name in sys.modules if name == "course" or name.startswith("course.")}
    with monkeypatch.context() as patch:
        for name in saved:
            patch.delitem(sys.modules, name)
        notebooks_raster = importlib.import_module("course.raster")         # the notebook's copy
        extra = [n for n in sys.modules if (n == "course" or n.startswith("course.")) and n not in saved]
    for name in extra:                                                       # leave nothing of it behind
        sys.modules.pop(name, None)
    assert notebooks_raster.Camera is not raster.Camera
    namespace = {"torch": torch, "raster": notebooks_raster}
    exec(SUPERSAMPLE_SOURCE, namespace)
    result = run_check("5.4", namespace["supersample"])
    assert (result.points, result.message) == (3, "")


def test_the_analysis_depends_on_the_graders_edges():
    """5.5 is answered by running the student's function: a constant exponent fails, and the reference's
    exponents are the lecture's: about -2 at generic slopes, -1 near the axes, -1.5 with jitter."""
    from course.grading.lecture05 import _lines
    generic, axes = _lines([31.7, 58.3, 121.4, 147.9], 121, 12, 9), _lines([0.4, 89.3, 179.2, 270.6], 122, 12, 9)
    ks = [1, 2, 4, 8, 16]
    assert -2.0 < float(_convergence(generic, 12, 9, ks)[1]) < -1.7
    assert -1.2 < float(_convergence(axes, 12, 9, ks)[1]) < -0.9
    assert -1.6 < float(_convergence(generic, 12, 9, ks, True)[1]) < -1.35
    constant = lambda lines, width, height, ks, jitter=False, seed=0: (                       # noqa: E731
        _convergence(lines, width, height, ks, jitter, seed)[0], -1.5)
    assert run_check("5.5", constant).points == 0
