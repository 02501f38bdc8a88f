"""The checks of lecture 3's graded tasks (rasterization): 3.1 inside_triangle, 3.2 barycentric,
3.3 zbuffer_resolve, 3.4 perspective_correct.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

import itertools

import torch

from .helpers import _call, _diagnose, _fmt, _num, _ref, _unpack, compare, generator, grade_parts, require, to_tensor
from .registry import task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


_TRIANGLE = [[1.2, 0.7], [6.3, 2.1], [2.5, 5.8]]                        # asymmetric, so axis flips show


def _winding(tri: torch.Tensor) -> str:
    """How the vertices run as seen on screen (x right, y down)."""
    d1, d2 = tri[1] - tri[0], tri[2] - tri[0]
    return "clockwise" if float(d1[0] * d2[1] - d1[1] * d2[0]) > 0 else "counter-clockwise"


def _points_off_edges(tri: torch.Tensor, n: int, seed: int, low=-0.5, high=7.5) -> torch.Tensor:
    """Seeded points in a box around ``tri``, none within 1e-3 of an edge's line (where rounding decides)."""
    p = low + (high - low) * torch.rand(n, 2, generator=generator(seed), dtype=torch.float64)
    t = tri.to(torch.float64)
    keep = torch.ones(n, dtype=torch.bool)
    for k in range(3):
        a, b = t[k], t[(k + 1) % 3]
        d = b - a
        keep &= ((d[0] * (p[:, 1] - a[1]) - d[1] * (p[:, 0] - a[0])).abs() / d.norm()) > 1e-3
    return p[keep]


def _tiled_square() -> list[torch.Tensor]:
    """A 4×4 square cut into 2×2 cells, each split into two triangles along alternating diagonals, with
    alternating windings: every interior edge is shared by two triangles."""
    triangles = []
    for i, j in itertools.product(range(2), range(2)):
        x, y = 2.0 * i, 2.0 * j
        a, b, c, d = [x, y], [x + 2, y], [x + 2, y + 2], [x, y + 2]
        pair = ([a, b, c], [a, c, d]) if (i + j) % 2 == 0 else ([a, b, d], [b, c, d])
        triangles += [torch.tensor(pair[0]), torch.tensor(pair[1][::-1])]
    return triangles


def _inside_with_rule(tri, points, top: bool, left: bool) -> torch.Tensor:
    """Coverage under a fill rule that takes the top (or bottom) and left (or right) edges: the top-left
    rule is ``top=left=True``; the other three are the mistakes of a sign flipped in one test or both."""
    edge = _ref("course.raster", "edge_function")
    t = tri.to(torch.float64)
    if float(edge(t[0], t[1], t[2])) < 0:
        t = t[[0, 2, 1]]                                                  # positive area, y down
    p = points.to(torch.float64)
    inside = torch.ones(len(p), dtype=torch.bool)
    for k in range(3):
        a, b = t[k], t[(k + 1) % 3]
        d = b - a
        owned = bool(d[1] < 0) if left else bool(d[1] > 0)                # left edges run up (-y) on screen
        if d[1] == 0:
            owned = bool(d[0] > 0) if top else bool(d[0] < 0)             # top edges run toward +x
        e = edge(a, b, p)
        inside &= (e > 0) | ((e == 0) & owned)
    return inside


def _fill_rule_variants(tri, points) -> list:
    left = ("a left edge runs upward on screen (b_y < a_y with y down, area positive): points on it are "
            "inside, points on a right edge (b_y > a_y) are not")
    top = ("a top edge is horizontal and runs toward +x (b_y == a_y, b_x > a_x, area positive): points on it "
           "are inside, points on a bottom edge (running toward -x) are not")
    return [(_inside_with_rule(tri, points, True, False), "your rule takes right edges instead of left ones: "
             + left),
            (_inside_with_rule(tri, points, False, True), "your rule takes bottom edges instead of top ones: "
             + top),
            (_inside_with_rule(tri, points, False, False), "your rule takes the bottom and right edges (both "
             "signs flipped: is the area positive before you test the edges?): " + left + "; " + top)]


@task("3.1", "inside_triangle", points=3, reference=("course.raster", "inside_triangle"))
def _check_inside_triangle(impl):
    ref = _ref("course.raster", "inside_triangle")

    def winding(order):
        tri = torch.tensor(_TRIANGLE)[order]
        points = _points_off_edges(tri, 80, seed=31).to(torch.float32)
        got, expected = _call(impl, tri, points), ref(tri, points)
        name = f"inside_triangle for a triangle whose vertices run {_winding(tri)} on screen"
        got_t = to_tensor(got, name)
        if got_t.shape == expected.shape and not got_t.bool().any() and expected.any():
            require(f"{name}: every point is outside; accept either winding (flip the edge-function signs "
                    "when the signed area is negative)")
        require(_diagnose(got, expected, name, [(~expected, "inside and outside are swapped: check the "
                                                 "signs of your edge functions")]))

    def shared_edges():
        grid = torch.arange(0.0, 4.01, 0.5)
        points = torch.stack(torch.meshgrid(grid, grid, indexing="xy"), -1).reshape(-1, 2)   # (81, 2)
        interior = ((points > 0) & (points < 4)).all(1)
        count = torch.zeros(len(points), dtype=torch.int64)
        for tri in _tiled_square():
            got = to_tensor(_call(impl, tri, points), "inside_triangle")
            if got.shape != (len(points),):
                require(compare(got, ref(tri, points), name="inside_triangle"))
            count += got.bool().to(torch.int64)
        for wrong, how in ((count > 1, "inside both"), (count == 0, "inside neither")):
            bad = (wrong & interior).nonzero()
            if len(bad):
                p = points[int(bad[0])]
                require(f"point ({_num(p[0])}, {_num(p[1])}) on an edge shared by two triangles is {how}: with "
                        "the top-left rule each shared edge belongs to exactly one triangle")
        for tri in _tiled_square():
            require(_diagnose(_call(impl, tri, points), ref(tri, points), "inside_triangle on the edges of "
                              f"triangle {_fmt(tri)} (top-left rule: points on a top or left edge are inside, "
                              "on a bottom or right edge outside)", _fill_rule_variants(tri, points)))

    def zero_area_and_float64():
        line = torch.tensor([[0.0, 0.0], [2.0, 1.0], [4.0, 2.0]], dtype=torch.float64)
        on_line = torch.tensor([[1.0, 0.5], [2.0, 1.0], [3.0, 1.5], [1.0, 1.0]], dtype=torch.float64)
        require(compare(_call(impl, line, on_line), ref(line, on_line),
                        name="inside_triangle for a zero-area triangle (it covers nothing)"))
        tri = torch.tensor(_TRIANGLE, dtype=torch.float64) * 1e3 + 5e3
        points = _points_off_edges(tri / 1e3 - 5, 50, seed=32) * 1e3 + 5e3
        require(compare(_call(impl, tri, points), ref(tri, points), name="inside_triangle (float64, large "
                        "coordinates)"))
    return grade_parts((1, "one winding", lambda: winding([0, 1, 2])),
                       (1, "the other winding", lambda: winding([0, 2, 1])),
                       (1, "shared edges, zero area, float64", lambda: (shared_edges(), zero_area_and_float64())))


@task("3.2", "barycentric", points=2, reference=("course.raster", "barycentric_2d"))
def _check_barycentric(impl):
    ref = _ref("course.raster", "barycentric_2d")

    def basic():
        for order in ([0, 1, 2], [0, 2, 1]):
            tri = torch.tensor(_TRIANGLE)[order]
            points = (torch.rand(40, 2, generator=generator(33)) * 9 - 1)          # inside and outside
            got, expected = _call(impl, tri, points), ref(tri, points)
            name = f"barycentric for a triangle whose vertices run {_winding(tri)} on screen"
            e64 = expected.to(torch.float64)
            variants = [(e64[:, p], "weights in the wrong order: column k is the weight of vertex tri[k] "
                         "(1 at tri[k], 0 on the opposite edge)")
                        for p in itertools.permutations(range(3)) if list(p) != [0, 1, 2]]
            variants.append((-e64, "signs flipped for this winding: divide by the signed area, which is "
                             "negative when the vertices run the other way"))
            message = _diagnose(got, expected, name, variants, atol=1e-4, rtol=1e-4)
            g = to_tensor(got, name)
            if message and g.shape == expected.shape and "wrong values" in message:
                sums = g.to(torch.float64).sum(-1)
                if torch.isfinite(sums).all() and (sums - 1).abs().max() > 1e-3:
                    message = f"{name}: the weights do not sum to 1: divide the edge functions by the area"
            require(message)

    def stress():
        line = torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
        points = torch.tensor([[0.5, 0.5], [1.0, 0.0], [3.0, 1.0]])
        got = to_tensor(_call(impl, line, points), "barycentric")
        if got.shape != (3, 3):
            require(compare(got, ref(line, points), name="barycentric for a zero-area triangle"))
        if not torch.isfinite(got).all():
            require("barycentric for a zero-area triangle returns NaN or inf: return finite weights (guard the "
                    "division by the area)")
        tri = torch.tensor(_TRIANGLE, dtype=torch.float64) + 1e4
        points = torch.rand(30, 2, generator=generator(34), dtype=torch.float64) * 9 - 1 + 1e4
        require(compare(_call(impl, tri, points), ref(tri, points), atol=1e-7, rtol=1e-7,
                        name="barycentric (float64, coordinates near 1e4)"))
    return grade_parts((1, "both windings", basic), (1, "zero-area triangle, float64", stress))


def _zbuffer_problems(out, pixel_index, depth, face_id, num_pixels, check_dtype) -> str | None:
    """One message for the first wrong pixel, in terms of the fragments that cover it."""
    face_map, depth_map = _unpack(out, ("face_map", "depth_map"), "zbuffer_resolve")
    ref_face, ref_depth = _ref("course.raster", "zbuffer_resolve")(pixel_index, depth, face_id, num_pixels)
    for got, expected, label in ((face_map, ref_face, "face_map"), (depth_map, ref_depth, "depth_map")):
        if got.shape != expected.shape or (check_dtype and got.dtype != expected.dtype):
            return compare(got, expected, name=f"zbuffer_resolve {label}", check_dtype=check_dtype)
    if not face_map.is_floating_point() or torch.isfinite(face_map).all():
        wrong = (face_map.to(torch.int64) != ref_face).nonzero()
        if len(wrong):
            p = int(wrong[0])
            return _zbuffer_pixel_message(p, int(face_map[p]), pixel_index, depth, face_id)
    message = compare(depth_map, ref_depth, name="zbuffer_resolve depth_map", check_dtype=check_dtype)
    if message and (torch.isinf(ref_depth) & ~torch.isinf(depth_map.to(torch.float64))).any():
        message += ": empty pixels have depth +inf"
    return message or compare(face_map, ref_face, name="zbuffer_resolve face_map", check_dtype=check_dtype)


def _zbuffer_pixel_message(p: int, got: int, pixel_index, depth, face_id) -> str:
    here = pixel_index == p
    fragments = sorted(zip(depth[here].tolist(), face_id[here].tolist()))       # (depth, face), nearest first
    if not fragments:
        return (f"zbuffer_resolve: pixel {p} has no fragment, so face_map must be -1 there (and depth_map +inf); "
                f"got face {got}")
    nearest_depth, nearest_face = fragments[0]
    if got == -1:
        return f"zbuffer_resolve: pixel {p} is covered (nearest: face {nearest_face}) but you left it empty"
    tied = sorted(f for d, f in fragments if d == nearest_depth)
    if got in tied:
        return (f"zbuffer_resolve: pixel {p}: faces {', '.join(map(str, tied))} are at the same depth "
                f"{_num(nearest_depth)}; ties go to the lower face id ({tied[0]}), you kept {got}")
    if got == fragments[-1][1]:
        return (f"zbuffer_resolve: pixel {p}: you kept the farthest fragment (face {got}, depth "
                f"{_num(fragments[-1][0])}); the z-buffer keeps the smallest depth (face {nearest_face})")
    return (f"zbuffer_resolve: pixel {p}: face {nearest_face} expected (depth {_num(nearest_depth)}), "
            f"got face {got}")


@task("3.3", "zbuffer_resolve", points=3, reference=("course.raster", "zbuffer_resolve"))
def _check_zbuffer_resolve(impl):
    def run(pixel_index, depth, face_id, num_pixels, check_dtype=False):
        pixel_index, face_id = (torch.tensor(x, dtype=torch.int64) for x in (pixel_index, face_id))
        depth = torch.as_tensor(depth, dtype=torch.float32) if not isinstance(depth, torch.Tensor) else depth
        out = _call(impl, pixel_index, depth, face_id, num_pixels)
        require(_zbuffer_problems(out, pixel_index, depth, face_id, num_pixels, check_dtype))

    def stress():
        run([], torch.zeros(0), [], 4)                                    # nothing drawn: all empty
        g = generator(35)
        m = 300
        depth = (torch.randint(1, 12, (m,), generator=g) * 0.25).to(torch.float64)   # many exact ties
        run(torch.randint(0, 16, (m,), generator=g).tolist(), depth, torch.randperm(m, generator=g).tolist(),
            16, check_dtype=True)
    return grade_parts(
        (1, "nearest fragment", lambda: run([3, 0, 3, 4, 0, 3, 1, 4, 2],
                                            [2.0, 1.5, 0.7, 4.0, 3.0, 1.1, 0.9, 2.5, 5.0],
                                            [4, 1, 7, 2, 0, 3, 5, 6, 8], 5)),
        (1, "empty pixels and ties", lambda: run([2, 0, 2, 4, 0], [0.5, 1.0, 0.5, 2.0, 1.0], [8, 6, 3, 1, 2], 7)),
        (1, "no fragments, many fragments, int64 and float64", stress))


@task("3.4", "perspective_correct", points=2, reference=("course.raster", "perspective_correct_bary"))
def _check_perspective_correct(impl):
    ref = _ref("course.raster", "perspective_correct_bary")

    def cases(dtype, stress):
        g = generator(36)
        b = torch.rand(8, 3, generator=g, dtype=torch.float64)
        b, z = b / b.sum(1, keepdim=True), 1 + 5 * torch.rand(8, 3, generator=g, dtype=torch.float64)
        if stress:
            b = torch.cat([b, torch.tensor([[1.0, 0, 0], [0, 0.3, 0.7], [0.2, 0.3, 0.5], [0.2, 0.3, 0.5]])])
            z = torch.cat([z, torch.tensor([[1e-3, 1e3, 1.0], [2.0, 1e-3, 1e3], [4.0, 4.0, 4.0],
                                            [1e-3, 1e-3, 1e3]])])
        b, z = b.to(dtype), z.to(dtype)
        b64, z64 = b.to(torch.float64), z.to(torch.float64)
        weighted = b64 * z64
        require(_diagnose(_call(impl, b, z), ref(b, z), f"perspective_correct({len(b)} fragments)", [
            (weighted / weighted.sum(1, keepdim=True), "you weighted by z; the weights are b_k / z_k, normalised"),
            (b64 / z64, "normalise: divide by Σ_j b_j / z_j so the weights sum to 1"),
            (b64, "returned bary_screen unchanged: divide each weight by its vertex's depth and normalise")],
            check_dtype=stress))
    return grade_parts((1, "fragments", lambda: cases(torch.float32, False)),
                       (1, "extreme depths, vertices, float64", lambda: cases(torch.float64, True)))
