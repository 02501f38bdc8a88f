"""The checks of lecture 7's graded tasks (ray tracing): 7.1 ray_triangle, 7.2 ray_aabb, 7.3 shadow_ray,
7.4 bvh_closest_hit, 7.5 area_light, 7.6 error_slope.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``; nothing here is public.

References: 7.1 is ``course.intersect.moller_trumbore`` with the hits behind the origin (t <= 0) removed;
7.2 is ``course.raytrace.ray_box`` (``_slab_reference``, in float64); 7.3 is brute force over every
triangle with ``intersect_triangles`` (``_shadow_reference``), the same answer as ``course.raytrace.visible``
on these scenes; 7.4 is ``BVH.intersect`` (the closest hit, t > 0); 7.5 is the area-light estimator written
here (``_area_reference``: visibility by brute force, each sample weighted by cos θ cos θ′ / r²); 7.6 is the
least-squares slope of log RMSE against log S (``_slope_reference``), run on estimators written here whose
exact answer is known (``_occluded_light``). A function that reaches a package function doing the task's work
scores 0 and is told so.
"""
from __future__ import annotations

import math

import torch

from .helpers import _call, _close, _ref, _unpack, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS

EPS = 1e-6                       # 7.3: hits with t <= EPS or t >= 1 - EPS do not block (t = 1 at the light)


def _mismatch(got: torch.Tensor, expected: torch.Tensor, where: torch.Tensor) -> bool:
    return bool(((got != expected) & where).any())


# ---------------------------------------------------------------------------------- 7.1 ray–triangle

def _triangle_reference(o, d, tris):
    t, bary, hit = _ref("course.intersect", "moller_trumbore")(o, d, tris)
    hit = hit & (t > 0)
    return torch.where(hit, t, torch.full_like(t, math.inf)), hit, t, bary


def _triangle_problem(impl, o, d, tris, label) -> str | None:
    name = f"ray_triangle({label})"
    t_exp, hit_exp, t_raw, bary = _triangle_reference(o, d, tris)
    t_got, hit_got = _unpack(_call(impl, o, d, tris), ("t", "hit"), "ray_triangle")
    if hit_got.shape != hit_exp.shape:
        return f"{name} hit: shape {tuple(hit_exp.shape)} expected, got {tuple(hit_got.shape)}"
    if hit_got.dtype != torch.bool:
        return f"{name} hit: return a bool tensor (True where the ray hits), got {str(hit_got.dtype)[6:]}"
    if t_got.shape != t_exp.shape:
        return f"{name} t: shape {tuple(t_exp.shape)} expected, got {tuple(t_got.shape)}"
    if not torch.equal(hit_got, hit_exp):
        raw_hit = torch.isfinite(t_raw)                                   # the reference's hits, any t
        e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
        facing = (torch.linalg.cross(e1, e2) * d).sum(1) < 0              # counter-clockwise seen from the ray
        on_edge = hit_exp & (bary == 0).any(1)
        wrong = hit_got != hit_exp
        only = lambda where: bool((wrong & ~where).sum() == 0)           # noqa: E731  every wrong ray is there
        if only(raw_hit & (t_raw <= 0) & hit_got):
            return (f"{name}: a triangle behind the ray's origin (t <= 0) counts as a hit: a ray goes forward "
                    "only, so require t > 0")
        if only(hit_exp & ~facing & ~hit_got):
            return (f"{name}: triangles seen from behind (clockwise from the ray) are missed: test both windings; "
                    "the determinant can be negative (reject only det == 0)")
        if only(on_edge & ~hit_got):
            return (f"{name}: rays through an edge or a vertex miss: a point on an edge has a barycentric weight "
                    "of exactly 0 and is inside, so compare with >= 0 and <= 1, not > 0 and < 1")
        bad = (hit_got != hit_exp).nonzero()[0, 0]
        return (f"{name} hit: {int((hit_got != hit_exp).sum())} of {hit_exp.numel()} rays wrong (first: ray "
                f"{int(bad)}, got {bool(hit_got[bad])}, expected {bool(hit_exp[bad])})")
    if bool((hit_exp == 0).any()) and not bool(torch.isinf(t_got[~hit_exp]).all() & (t_got[~hit_exp] > 0).all()):
        return f"{name} t: where a ray misses, t must be +inf"
    scale = d.norm(dim=1)
    if hit_exp.any() and compare(t_got[hit_exp], t_exp[hit_exp], check_dtype=False) is not None and \
            compare(t_got[hit_exp], (t_exp * scale)[hit_exp], check_dtype=False) is None:
        return (f"{name} t: that is the distance along the normalised direction: t is in the units of the "
                "direction given, the hit point is o + t d")
    msg = compare(t_got, t_exp, name=f"{name} t", check_dtype=o.dtype == torch.float64)
    return msg


def _random_rays(n, seed, dtype):
    """n rays, each with its own triangle; about half of them hit it, some from behind, some behind the
    origin."""
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    tris = r(n, 3, 3) * 2 - 1
    w = r(n, 3) * 1.6 - 0.3                                               # weights, some outside [0, 1]
    w = w / w.sum(1, keepdim=True)
    target = (w[:, :, None] * tris).sum(1)
    o = r(n, 3) * 6 - 3
    d = (target - o) * (0.5 + r(n, 1))
    d[: n // 8] = -d[: n // 8]                                            # the triangle behind the origin
    return o.to(dtype), d.to(dtype), tris.to(dtype)


def _edge_rays(dtype=torch.float64):
    """Rays through the shared diagonal and the corners of a unit square split in two, both windings,
    axis-aligned and oblique."""
    f = lambda v: torch.tensor(v, dtype=dtype)                           # noqa: E731
    A = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]
    B = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]
    origins, dirs, tris = [], [], []
    for target in ([0.5, 0.5, 0.0], [0.25, 0.25, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0],
                   [0.5, 0.0, 0.0]):
        for o in ([target[0], target[1], 2.0], [target[0], target[1], -1.0], [target[0] + 1, target[1] + 2, 4.0]):
            for tri in (A, B):
                origins.append(o)
                dirs.append([t - s for t, s in zip(target, o)])
                tris.append(tri)
    return f(origins), f(dirs), f(tris)


def _parallel_rays(dtype=torch.float64):
    """Rays in the triangle's plane, parallel to it above it, zero direction components, and a triangle
    behind the origin along the ray."""
    f = lambda v: torch.tensor(v, dtype=dtype)                           # noqa: E731
    tri = [[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 1.0]]
    o = [[-1.0, 0.5, 1.0], [-1.0, 0.5, 2.0], [0.5, 0.5, 0.0], [0.5, 0.5, 3.0], [0.5, 0.5, 3.0], [3.0, 3.0, 0.0],
         [0.5, 0.5, 0.0]]
    d = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0],
         [0.0, 0.0, 1e-3]]
    return f(o), f(d), f([tri] * len(o))


@task("7.1", "ray_triangle", points=3, reference=("course.intersect", "moller_trumbore"))
def _check_ray_triangle(impl):
    forbidden = forbidden_call(impl, "ray_triangle", [("course.intersect", "intersect_triangles"),
                                                  ("course.bvh", "BVH")])
    if forbidden:
        return 0, forbidden

    def random():
        require(_triangle_problem(impl, *_random_rays(64, 71, torch.float32), "64 random rays, float32"))

    def edges():
        require(_triangle_problem(impl, *_edge_rays(), "rays through a shared edge and vertices"))

    def stress():
        require(_triangle_problem(impl, *_parallel_rays(), "parallel rays, zero direction components"))
        o, d, tris = _random_rays(40, 72, torch.float64)
        require(_triangle_problem(impl, o * 1e3 + 5e3, d * 1e3, tris * 1e3 + 5e3, "far and large, float64"))
    return grade_parts((1, "random rays and triangles", random),
                       (1, "rays through a shared edge and vertices", edges),
                       (1, "parallel rays, a triangle behind the origin, far away, float64", stress))


# ------------------------------------------------------------------------------------ 7.2 the slab test

def _slab_reference(o, d, lo, hi):
    """The slab test, float64, as the task states it: (hit, t_near, t_far) from course.raytrace.ray_box. An
    axis with d = 0 is (-inf, inf) when lo <= o <= hi on it (the ray runs in or between its planes), else empty."""
    o, d, lo, hi = (x.to(torch.float64) for x in (o, d, lo, hi))
    with torch.no_grad():
        return _ref("course.raytrace", "ray_box")(o, d, lo, hi)


def _slab_problem(impl, o, d, lo, hi, label) -> str | None:
    name = f"ray_aabb({label})"
    hit_exp, near_exp, far_exp = _slab_reference(o, d, lo, hi)
    hit, near, far = _unpack(_call(impl, o, d, lo, hi), ("hit", "t_near", "t_far"), "ray_aabb")
    for value, expected, what in ((hit, hit_exp, "hit"), (near, near_exp, "t_near"), (far, far_exp, "t_far")):
        if value.shape != expected.shape:
            return f"{name} {what}: shape {tuple(expected.shape)} expected, got {tuple(value.shape)}"
    if hit.dtype != torch.bool:
        return f"{name} hit: return a bool tensor (True where the ray meets the box), got {str(hit.dtype)[6:]}"
    if not torch.equal(hit, hit_exp):
        zero = (d == 0).any(-1) if d.dim() == 2 else d == 0
        on_plane = ((d == 0) & ((o == lo) | (o == hi))).any(-1)
        behind = hit_exp.logical_not() & (near_exp <= far_exp) & (far_exp < 0)
        inside = hit_exp & (near_exp < 0)
        wrong = hit != hit_exp
        n_wrong = int(wrong.sum())
        if bool((wrong & on_plane).sum() == n_wrong):
            return (f"{name}: a ray with d = 0 on an axis whose origin lies exactly on that slab's plane (o = lo or "
                    "o = hi) gives 0 / 0 = NaN: handle d == 0 by itself (the slab is everything when lo <= o <= hi, "
                    "nothing otherwise)")
        if bool((wrong & behind).sum() == n_wrong):
            return (f"{name}: a box behind the origin (t_far < 0) counts as a hit: require t_far >= 0 as well as "
                    "t_near <= t_far")
        if bool((wrong & inside & ~hit).sum() == n_wrong):
            return (f"{name}: an origin inside the box (t_near < 0 <= t_far) is a hit: the ray starts inside; "
                    "require t_far >= 0, not t_near >= 0")
        if bool((wrong & hit_exp & (near_exp == far_exp)).sum() == n_wrong):
            return (f"{name}: a ray that touches the box at one point (t_near == t_far: an edge or a corner) is a "
                    "hit: the box is closed, compare with <=")
        if bool((wrong & zero).sum() == n_wrong):
            return (f"{name}: rays with a zero direction component go wrong: 1 / 0 = ±inf makes that slab "
                    "everything or nothing; an origin between the planes is inside it")
        a, b = (lo - o) / d, (hi - o) / d
        no_swap_near, no_swap_far = a.amax(-1), b.amin(-1)
        if torch.equal(hit, (no_swap_near <= no_swap_far) & (no_swap_far >= 0)) or \
                bool((wrong & (d < 0).any(-1)).sum() == n_wrong) and not bool((wrong & ~(d < 0).any(-1)).any()):
            return (f"{name}: rays with a negative direction component go wrong: then (hi - o) / d is the entry and "
                    "(lo - o) / d the exit; take the min and max of the two per axis")
        bad = int(wrong.nonzero()[0, 0])
        return (f"{name} hit: {n_wrong} of {hit_exp.numel()} rays wrong (first: ray {bad}, got {bool(hit[bad])}, "
                f"expected {bool(hit_exp[bad])})")
    if hit_exp.any():
        ne, fe, ng, fg = near_exp[hit_exp], far_exp[hit_exp], near[hit_exp], far[hit_exp]
        if compare(ng, ne, check_dtype=False) is not None and compare(ng, ne.clamp_min(0), check_dtype=False) is None:
            return (f"{name} t_near: return the slab interval's entry as it is: it is negative when the origin is "
                    "inside the box (do not clamp it to 0)")
        for got, expected, what in ((ng, ne, "t_near"), (fg, fe, "t_far")):
            msg = compare(got, expected.to(o.dtype), name=f"{name} {what} (where hit)",
                          check_dtype=o.dtype == torch.float64)
            if msg:
                return msg
    return None


def _random_boxes(n, seed, dtype):
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    centre, half = r(n, 3) * 2 - 1, 0.1 + r(n, 3)
    o = r(n, 3) * 8 - 4
    target = centre + (r(n, 3) * 2 - 1) * half * 1.6                      # about half inside the box
    d = (target - o) * (0.3 + r(n, 1))
    d[: n // 8] = -d[: n // 8]                                            # the box behind the origin
    return o.to(dtype), d.to(dtype), (centre - half).to(dtype), (centre + half).to(dtype)


def _axis_rays(dtype=torch.float64):
    """The box [0, 1]³; rays with zero direction components, origins on the slab planes, inside, behind,
    touching an edge and a corner."""
    f = lambda v: torch.tensor(v, dtype=dtype)                           # noqa: E731
    o = [[-1.0, 0.5, 0.5], [-1.0, 0.0, 0.5], [-1.0, 1.0, 1.0], [-1.0, 1.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5],
         [2.0, 0.5, 0.5], [-1.0, -1.0, 0.5], [-1.0, -1.0, 0.0], [0.0, 0.5, 0.5], [1.0, 0.2, 0.3],
         [-1.0, 0.0, 0.0], [0.5, 0.5, -2.0], [0.5, 0.5, 2.0], [0.0, 2.0, 0.5]]
    d = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 2.0, 0.5],
         [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0],
         [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -0.5], [1.0, -1.0, 0.0]]
    n = len(o)
    return f(o), f(d), f([[0.0, 0.0, 0.0]] * n), f([[1.0, 1.0, 1.0]] * n)


@task("7.2", "ray_aabb", points=2, reference=("course.intersect", "ray_box"))
def _check_ray_aabb(impl):
    forbidden = forbidden_call(impl, "ray_aabb", [("course.intersect", "_slab"), ("course.bvh", "BVH")])
    if forbidden:
        return 0, forbidden

    def random():
        require(_slab_problem(impl, *_random_boxes(64, 73, torch.float32), "64 random rays and boxes, float32"))

    def negative():
        o, d, lo, hi = _random_boxes(64, 74, torch.float64)
        d = -d.abs()                                                      # every component negative
        o = torch.where(torch.rand(64, 1, generator=generator(75), dtype=torch.float64) < 0.5, o.abs() + 1, o)
        require(_slab_problem(impl, o, d, lo, hi, "negative direction components, float64"))

    def stress():
        require(_slab_problem(impl, *_axis_rays(), "zero components, origins on slab planes, inside, behind"))
        o, d, lo, hi = _random_boxes(32, 76, torch.float64)
        require(_slab_problem(impl, o * 1e4, d * 1e-3, lo * 1e4, hi * 1e4, "large boxes, short directions"))
    def basic():
        random()
        negative()
    return grade_parts((1, "random rays and boxes, negative direction components", basic),
                       (1, "zero direction components, origins on a slab plane, inside and behind", stress))


# ----------------------------------------------------------------------------------------- 7.3 shadow rays

def _shadow_reference(points, light, tris):
    """Brute force, float64: (N,) True where no triangle meets the segment p → light at EPS < t < 1 - EPS."""
    p, L, T = (x.to(torch.float64) for x in (points, light, tris))
    N, F = p.shape[0], T.shape[0]
    L = L.expand(N, 3)
    o = p.repeat_interleave(F, 0)
    d = (L - p).repeat_interleave(F, 0)
    t, _, hit = _ref("course.raytrace", "intersect_triangles")(o, d, T.repeat(N, 1, 1))
    t = t.view(N, F)
    hit = hit.view(N, F)
    blocked = (hit & (t > EPS) & (t < 1 - EPS)).any(1)
    ray_blocked = (hit & (t > EPS)).any(1)                               # the whole ray, not the segment
    return ~blocked, ~ray_blocked, t, hit


def _shadow_problem(impl, points, light, tris, label, on_surface=None) -> str | None:
    name = f"shadow_ray({label})"
    expected, ray_free, t, hit = _shadow_reference(points, light, tris)
    got = to_tensor(_call(impl, points, light, tris), name)
    if got.shape != expected.shape:
        return f"{name}: shape {tuple(expected.shape)} expected, got {tuple(got.shape)}"
    if got.dtype != torch.bool:
        return f"{name}: return a bool tensor (True where the point sees the light), got {str(got.dtype)[6:]}"
    if torch.equal(got, expected):
        return None
    wrong = got != expected
    n = int(wrong.sum())
    if torch.equal(got, ray_free) and not torch.equal(ray_free, expected):
        return (f"{name}: an occluder beyond the light shadows the point: only hits between the point and the "
                "light count, 0 < t < 1 with d = light - point")
    if on_surface is not None and bool((wrong & on_surface & ~got).sum() == n):
        return (f"{name}: points on a surface shadow themselves (shadow acne): the ray meets the point's own "
                f"triangle at t = 0 (give or take rounding): ignore hits with t <= {EPS:g}")
    back = torch.where(hit & (t < 0) & (t > -1e6), True, False).any(1)
    if bool((wrong & ~got & back).sum() == n):
        return (f"{name}: a triangle behind the point (on the side away from the light) shadows it: the shadow "
                "ray goes from the point towards the light, d = light - point, and only t > 0 counts")
    if torch.equal(got, ~expected):
        return f"{name}: True and False are swapped: return True where the point *sees* the light (not shadowed)"
    bad = int(wrong.nonzero()[0, 0])
    return (f"{name}: {n} of {expected.numel()} points wrong (first: point {bad}, got {bool(got[bad])}, "
            f"expected {bool(expected[bad])})")


def _shadow_scene(dtype=torch.float64):
    """A ground square (two triangles, y = 0), a floating square occluder (y = 1) and a tilted triangle."""
    f = lambda v: torch.tensor(v, dtype=dtype)                           # noqa: E731
    tris = f([[[-3.0, 0.0, -3.0], [-3.0, 0.0, 3.0], [3.0, 0.0, 3.0]],
              [[-3.0, 0.0, -3.0], [3.0, 0.0, 3.0], [3.0, 0.0, -3.0]],
              [[-0.5, 1.0, -0.5], [0.5, 1.0, 0.5], [0.5, 1.0, -0.5]],
              [[-0.5, 1.0, -0.5], [-0.5, 1.0, 0.5], [0.5, 1.0, 0.5]],
              [[1.0, 0.5, 1.0], [2.0, 1.5, 1.0], [1.5, 1.0, 2.0]]])
    return tris


@task("7.3", "shadow_ray", points=2, reference=("course.raytrace", "visible"))
def _check_shadow_ray(impl):
    forbidden = forbidden_call(impl, "shadow_ray", [("course.bvh", "BVH"),
                                                ("course.intersect", "moller_trumbore")])
    if forbidden:
        return 0, forbidden
    tris = _shadow_scene()

    def above():
        g = generator(77)
        p = torch.rand(48, 3, generator=g, dtype=torch.float64) * 4 - 2
        p[:, 1] = 0.2 + 0.6 * p[:, 1].abs() / 2                           # between the ground and the occluder
        require(_shadow_problem(impl, p.float(), torch.tensor([0.2, 3.0, 0.1]), tris.float(),
                                "48 points under a square, float32"))

    def beyond():
        g = generator(78)
        p = torch.rand(40, 3, generator=g, dtype=torch.float64) * 2 - 1
        p[:, 1] = 0.3
        light = torch.tensor([0.1, 0.7, -0.2], dtype=torch.float64)       # below the occluder
        require(_shadow_problem(impl, p, light, tris, "the light below the occluder, float64"))
        q = torch.rand(40, 3, generator=generator(79), dtype=torch.float64) * 2 - 1
        q[:, 1] = 2.0                                                      # above the occluder, light above too
        require(_shadow_problem(impl, q, torch.tensor([0.0, 4.0, 0.0], dtype=torch.float64), tris,
                                "points above everything, float64"))

    def surface():
        g = generator(80)
        p = torch.rand(64, 3, generator=g, dtype=torch.float64) * 5 - 2.5
        p[:, 1] = 0.0                                                      # on the ground
        on = torch.ones(64, dtype=torch.bool)
        require(_shadow_problem(impl, p, torch.tensor([0.3, 3.0, 0.2], dtype=torch.float64), tris,
                                "points on the ground, float64", on_surface=on))
        w = torch.rand(32, 3, generator=g, dtype=torch.float64) + 0.05
        w = w / w.sum(1, keepdim=True)
        q = w @ tris[4]                                                    # on the tilted triangle (rounded)
        require(_shadow_problem(impl, q, torch.tensor([1.2, 4.0, 1.1], dtype=torch.float64), tris,
                                "points on a tilted triangle", on_surface=torch.ones(32, dtype=torch.bool)))
        v = tris[2:, :, :].reshape(-1, 3)                                  # the occluders' own corners
        require(_shadow_problem(impl, v, torch.tensor([0.3, 5.0, 0.2], dtype=torch.float64), tris,
                                "points at the occluders' corners",
                                on_surface=torch.ones(v.shape[0], dtype=torch.bool)))
    def segment():
        above()
        beyond()
    return grade_parts((1, "points under an occluder, occluders beyond the light and behind the point", segment),
                       (1, "points on surfaces and at vertices (self-shadowing), float64", surface))


# ------------------------------------------------------------------------ 7.4 BVH traversal with a stack

class _Tree:
    """The flat tensors of a ``course.bvh.BVH``, and nothing else (no method that would do the traversal)."""

    def __init__(self, bvh):
        self.boxes, self.left, self.first, self.count = bvh.boxes, bvh.left, bvh.first, bvh.count
        self.order, self.tris = bvh.order, bvh.tris


def _two_spheres():
    """Two icospheres, one in front of the other (so the first leaf hit is often not the nearest), float64."""
    icosphere, mesh = _ref("course.models", "icosphere"), _ref("course.mesh", "Mesh")
    a = icosphere(2, radius=0.8, dtype=torch.float64)
    b = icosphere(1, radius=0.5, dtype=torch.float64)
    verts = torch.cat([a.verts + torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64),
                       b.verts + torch.tensor([-0.4, 0.2, 1.2], dtype=torch.float64)])
    faces = torch.cat([a.faces, b.faces + a.verts.shape[0]])
    return mesh(verts, faces)


def _traversal_rays(n, seed, inside=False):
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    if inside:                                                            # from inside the big sphere
        o = (r(n, 3) * 2 - 1) * 0.3 + torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64)
        d = r(n, 3) * 2 - 1
    else:                                                                 # from outside, aimed near the spheres
        o = (r(n, 3) * 2 - 1) * 0.5 + torch.tensor([0.0, 0.0, 4.0], dtype=torch.float64)
        d = (r(n, 3) * 2 - 1) * torch.tensor([1.2, 1.2, 0.5], dtype=torch.float64) - torch.tensor([0, 0, 4.0],
                                                                                               dtype=torch.float64)
    return o, d


def _traversal_problem(impl, bvh, o, d, label) -> str | None:
    name = f"bvh_closest_hit({label})"
    hits = bvh.intersect(o, d, t_min=0.0)
    t_exp, f_exp = hits.t, hits.face_id
    t_got, f_got = _unpack(_call(impl, o, d, _Tree(bvh)), ("t", "face_id"), "bvh_closest_hit")
    for got, exp, what in ((t_got, t_exp, "t"), (f_got, f_exp, "face_id")):
        if got.shape != exp.shape:
            return f"{name} {what}: shape {tuple(exp.shape)} expected, got {tuple(got.shape)}"
    if f_got.dtype != torch.int64:
        return f"{name} face_id: return an int64 tensor (the face id, -1 on a miss), got {str(f_got.dtype)[6:]}"
    if not torch.equal(f_got, f_exp):
        wrong = f_got != f_exp
        n = int(wrong.sum())
        got_hit, exp_hit = f_got >= 0, f_exp >= 0
        slot = torch.full_like(f_exp, -1)
        slot[exp_hit] = bvh._slot[f_exp[exp_hit]]
        if torch.equal(f_got, slot) and not torch.equal(slot, f_exp):
            return (f"{name}: face_id holds the triangle's slot in tree.tris, not its face id: the face of slot s "
                    "is tree.order[s]")
        if bool((wrong & exp_hit & ~got_hit).sum() == n):
            return (f"{name}: {n} rays that hit the mesh miss: a ray can meet both children's boxes, so push both "
                    "(the box the ray enters first is not always the one with the nearest hit)")
        if bool((wrong & got_hit & exp_hit).sum() == n):
            farther = bool((t_got[wrong] > t_exp[wrong]).all())
            if farther:
                return (f"{name}: {n} rays return a hit that is not the nearest: do not stop at the first leaf with "
                        "a hit; keep popping, and skip only the boxes the ray enters beyond the closest hit so far")
        bad = int(wrong.nonzero()[0, 0])
        return (f"{name} face_id: {n} of {f_exp.numel()} rays wrong (first: ray {bad}, got {int(f_got[bad])}, "
                f"expected {int(f_exp[bad])})")
    if bool((~(f_exp >= 0)).any()) and not bool((torch.isinf(t_got[f_exp < 0]) & (t_got[f_exp < 0] > 0)).all()):
        return f"{name} t: where a ray misses, t must be +inf"
    return compare(t_got, t_exp, name=f"{name} t", check_dtype=False)


@task("7.4", "bvh_closest_hit", points=5, reference=("course.bvh", "BVH.intersect"))
def _check_bvh_closest_hit(impl):
    forbidden = forbidden_call(impl, "bvh_closest_hit", [("course.bvh", "BVH"), ("course.raytrace", "raycast"),
                                                         ("course.intersect", "intersect_triangles"),
                                                         ("course.intersect", "moller_trumbore")])
    if forbidden:
        return 0, forbidden
    bvh = _ref("course.bvh", "BVH")(_two_spheres())

    def outside():
        require(_traversal_problem(impl, bvh, *_traversal_rays(40, 81), "40 rays at two spheres"))

    def nearest():
        o, d = _traversal_rays(40, 82)
        o = o * torch.tensor([1.0, 1.0, -1.0], dtype=torch.float64)    # from behind: the big sphere first
        d = d * torch.tensor([1.0, 1.0, -1.0], dtype=torch.float64)
        require(_traversal_problem(impl, bvh, o, d, "40 rays from the other side"))

    def inside():
        require(_traversal_problem(impl, bvh, *_traversal_rays(40, 83, inside=True), "40 rays from inside a sphere"))
        small = _ref("course.bvh", "BVH")(_two_spheres(), leaf_size=1)
        require(_traversal_problem(impl, small, *_traversal_rays(24, 84), "a BVH with one face per leaf"))
    return grade_parts((2, "rays from outside at two spheres", outside),
                       (2, "the nearest hit when the first leaf reached holds a farther one", nearest),
                       (1, "rays from inside a sphere, a tree with one face per leaf", inside))


# ----------------------------------------------------------------------------- 7.5 an area light's light

def _area_reference(points, normals, samples, light_normal, area, tris, *, cos_light=True, inv_r2=True,
                    scale=True, clamp=True, shadows=True):
    """E (N,) = A / S Σ_s V cos θ cos θ′ / r², radiance 1, float64; the keywords switch off one piece each
    (the typical mistakes). V by brute force, blocked by hits at EPS < t < 1 - EPS on the segment."""
    p, n, y, nl, T = (x.to(torch.float64) for x in (points, normals, samples, light_normal, tris))
    N, S, F = y.shape[0], y.shape[1], T.shape[0]
    w = y - p[:, None]                                                    # (N, S, 3) towards the samples
    r2 = (w * w).sum(-1)
    u = w / r2.sqrt()[..., None]
    n = n / n.norm(dim=1, keepdim=True)
    nl = nl / nl.norm()
    cos_p, cos_l = (u * n[:, None]).sum(-1), -(u @ nl)
    if clamp:
        cos_p, cos_l = cos_p.clamp_min(0), cos_l.clamp_min(0)
    weight = cos_p * (cos_l if cos_light else 1.0) / (r2 if inv_r2 else 1.0)
    if shadows:
        o = p.repeat_interleave(S, 0).repeat_interleave(F, 0)
        d = w.reshape(-1, 3).repeat_interleave(F, 0)
        t, _, hit = _ref("course.intersect", "intersect_triangles")(o, d, T.repeat(N * S, 1, 1))
        blocked = (hit & (t > EPS) & (t < 1 - EPS)).view(N, S, F).any(-1)
        weight = weight * (~blocked)
    return weight.sum(1) * (float(area) / S if scale else 1.0 / S)


def _area_scene(seed, n=24, grid=3, facing_away=False):
    """Points on the ground and on a tilted wall, a 0.8 x 0.5 light at height 2 facing down (stratified samples),
    a square occluder at height 1; some points see the light from behind it or lie above its plane."""
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    p = r(n, 3) * torch.tensor([3.0, 0.0, 3.0], dtype=torch.float64) - torch.tensor([1.5, 0, 1.5], dtype=torch.float64)
    nrm = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(n, 3).clone()
    k = n // 4
    nrm[:k] = torch.nn.functional.normalize(r(k, 3) * 2 - 1, dim=1)       # tilted: some face away from the light
    if facing_away:
        p[k:2 * k, 1] = 2.5                                               # above the light: behind its surface
    corner = torch.tensor([-0.4, 2.0, -0.25], dtype=torch.float64)
    e1, e2 = torch.tensor([0.8, 0.0, 0.0], dtype=torch.float64), torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64)
    cells = torch.arange(grid, dtype=torch.float64)
    i, j = torch.meshgrid(cells, cells, indexing="ij")
    uv = (torch.stack([i.reshape(-1), j.reshape(-1)], 1) + r(n, grid * grid, 2)) / grid
    samples = corner + uv[..., :1] * e1 + uv[..., 1:] * e2                # (N, S, 3)
    tris = torch.tensor([[[-0.5, 1.0, -0.5], [-0.5, 1.0, 0.5], [0.5, 1.0, 0.5]],
                         [[-0.5, 1.0, -0.5], [0.5, 1.0, 0.5], [0.5, 1.0, -0.5]]], dtype=torch.float64)
    return p, nrm, samples, torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64), 0.4, tris


def _area_problem(impl, scene, label) -> str | None:
    name = f"area_light({label})"
    expected = _area_reference(*scene)
    got = to_tensor(_call(impl, *scene), name)
    if got.shape != expected.shape:
        return f"{name}: shape {tuple(expected.shape)} expected, got {tuple(got.shape)}"
    if compare(got, expected, name=name, check_dtype=False) is None:
        return None
    variants = [
        (dict(cos_light=False), "the light's cosine is missing: a sample weighs cos θ cos θ′ / r², θ′ between "
                                "the light's normal and the direction back to the point"),
        (dict(inv_r2=False), "the 1 / r² is missing (or the cosines are taken with the direction to the sample "
                             "before dividing it by its length r, which cancels it): a sample's solid angle falls "
                             "with the square of its distance, and cos θ, cos θ′ are dot products of unit vectors"),
        (dict(scale=False), "the light's area is missing: the estimate of the integral over the light is "
                            "A / S times the sum of the samples' weights (A = area)"),
        (dict(clamp=False), "negative cosines count: a point behind which the light lies (cos θ < 0), or a sample "
                            "seen from behind the light (cos θ′ < 0), receives nothing: clamp each cosine at 0"),
        (dict(shadows=False), "nothing is shadowed: a sample counts only when the segment from the point to it is "
                              "free (a hit at 1e-6 < t < 1 - 1e-6 blocks it)"),
    ]
    for switch, explanation in variants:
        alternative = _area_reference(*scene, **switch)
        if _close(got, alternative, 1e-7) and not _close(expected, alternative, 1e-7):
            return f"{name}: {explanation}"
    return compare(got, expected, name=name, check_dtype=False)


@task("7.5", "area_light", points=4)
def _check_area_light(impl):
    forbidden = forbidden_call(impl, "area_light", [("course.raytrace", "visible"), ("course.bvh", "BVH"),
                                                    ("course.intersect", "intersect_triangles"),
                                                    ("course.intersect", "moller_trumbore")])
    if forbidden:
        return 0, forbidden

    def ground():
        scene = list(_area_scene(85))
        scene[1] = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(24, 3).clone()
        require(_area_problem(impl, tuple(scene), "points on the ground under a light and an occluder"))

    def tilted():
        require(_area_problem(impl, _area_scene(86), "tilted points, some facing away from the light"))

    def behind():
        require(_area_problem(impl, _area_scene(87, facing_away=True), "points above the light's plane"))
        scene = list(_area_scene(88, n=16, grid=4))
        scene[1] = scene[1] * 3.0                                         # normals that are not unit length
        scene[3] = scene[3] * 2.0
        require(_area_problem(impl, tuple(scene), "normals of any length"))
    return grade_parts((2, "points on the ground, a light, an occluder", ground),
                       (1, "tilted points, some facing away from the light", tilted),
                       (1, "points behind the light's plane, normals of any length", behind))


# ------------------------------------------------------------------------ 7.6 the error against samples

def _slope_reference(estimate, exact, counts, seeds):
    """RMSE (K,) pooled over seeds and points for each count, and the least-squares slope of log RMSE on log S."""
    exact = exact.to(torch.float64)
    rmse = torch.stack([torch.stack([((to_tensor(estimate(int(S), int(s))).to(torch.float64) - exact) ** 2)
                                     for s in seeds]).mean().sqrt() for S in counts])
    x, y = torch.log(torch.tensor(counts, dtype=torch.float64)), rmse.log()
    slope = ((x - x.mean()) * (y - y.mean())).sum() / ((x - x.mean()) ** 2).sum()
    return rmse, float(slope)


def _occluded_light(n_points, seed, stratified=True, size=0.6):
    """(estimate, exact): the visible fraction of a unit-square light at height 2 over points on the ground,
    partly hidden by a square occluder of side ``size`` at height 1 (parallel to it). Exact: the occluder,
    projected from the point onto the light's plane, is a square; the light minus their overlap is visible.
    The estimate draws S samples (stratified on a grid when S is a square, else independent) per point."""
    g = generator(seed)
    p = torch.rand(n_points, 2, generator=g, dtype=torch.float64) * 1.6 - 0.8   # (x, z) on the ground
    lo_occ, hi_occ = torch.tensor(-size / 2), torch.tensor(size / 2)
    scale = 2.0                                                           # height 1 → 2 doubles offsets from p
    lo_p, hi_p = p + (lo_occ - p) * scale, p + (hi_occ - p) * scale      # (N, 2) its shadow on the light
    overlap = (torch.minimum(hi_p, torch.tensor(0.5)) - torch.maximum(lo_p, torch.tensor(-0.5))).clamp_min(0)
    exact = 1 - overlap.prod(1)

    def estimate(S, s):
        gs = generator(1000 * seed + 7 * S + s)
        grid = math.isqrt(S)
        if stratified and grid * grid == S:
            cells = torch.arange(grid, dtype=torch.float64)
            i, j = torch.meshgrid(cells, cells, indexing="ij")
            uv = (torch.stack([i.reshape(-1), j.reshape(-1)], 1) + torch.rand(n_points, S, 2, generator=gs,
                                                                              dtype=torch.float64)) / grid
        else:
            uv = torch.rand(n_points, S, 2, generator=gs, dtype=torch.float64)
        y = uv - 0.5                                                      # (N, S, 2) on the light
        q = (p[:, None] + y) / 2                                          # where the segment crosses height 1
        blocked = ((q >= lo_occ) & (q <= hi_occ)).all(-1)
        return (~blocked).to(torch.float64).mean(1)
    return estimate, exact


def _slope_problem(impl, estimate, exact, counts, seeds, label) -> str | None:
    name = f"error_slope({label})"
    rmse_exp, slope_exp = _slope_reference(estimate, exact, counts, seeds)
    out = _call(impl, estimate, exact, list(counts), list(seeds))
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        return f"{name}: return a tuple (rmse, slope), got {type(out).__name__}"
    rmse, slope = to_tensor(out[0], f"{name} rmse"), out[1]
    try:
        slope = torch.as_tensor(slope, dtype=torch.float64).detach()
    except (TypeError, ValueError, RuntimeError):
        return f"{name} slope: a number expected, got {type(out[1]).__name__}"
    if rmse.shape != rmse_exp.shape:
        return f"{name} rmse: shape {tuple(rmse_exp.shape)} expected (one per sample count), got {tuple(rmse.shape)}"
    if not _close(rmse, rmse_exp, 1e-9):
        per_seed = torch.stack([torch.stack([((estimate(S, s) - exact) ** 2).mean().sqrt() for s in seeds]).mean()
                                for S in counts])
        mae = torch.stack([torch.stack([(estimate(S, s) - exact).abs() for s in seeds]).mean() for S in counts])
        if _close(rmse, rmse_exp ** 2, 1e-9):
            return f"{name} rmse: that is the mean squared error: take its square root (RMSE)"
        if _close(rmse, mae, 1e-9):
            return f"{name} rmse: that is the mean absolute error: the task asks for the root of the mean square"
        if _close(rmse, per_seed, 1e-9):
            return (f"{name} rmse: the RMSE of each seed, averaged: pool the squared errors of every seed and point "
                    "first, then take one square root per sample count")
        return compare(rmse, rmse_exp, name=f"{name} rmse", check_dtype=False)
    if slope.numel() != 1:
        return f"{name} slope: one number expected, got shape {tuple(slope.shape)}"
    got = float(slope.reshape(-1)[0])
    if abs(got - slope_exp) <= 1e-9 * max(1.0, abs(slope_exp)):
        return None
    x, y = torch.log(torch.tensor(counts, dtype=torch.float64)), rmse_exp.log()
    ends = float((y[-1] - y[0]) / (x[-1] - x[0]))
    if abs(got + slope_exp) <= 1e-9 * max(1.0, abs(slope_exp)):
        return f"{name} slope: the sign is flipped: the error falls, so the slope of log RMSE against log S is negative"
    if abs(got - ends) <= 1e-9 * max(1.0, abs(ends)):
        return (f"{name} slope: that is the slope between the first and last points: fit a straight line to all "
                "the points (least squares)")
    if abs(got - 2 * slope_exp) <= 1e-9 * max(1.0, abs(slope_exp)):
        return f"{name} slope: twice the expected slope: fit log RMSE, not log of the squared error"
    return f"{name} slope: got {got:.6g}, expected {slope_exp:.6g} (least squares of log RMSE on log S)"


@task("7.6", "error_slope", points=3)
def _check_error_slope(impl):
    def stratified():
        estimate, exact = _occluded_light(48, 90)
        require(_slope_problem(impl, estimate, exact, (4, 16, 64, 256), (0, 1, 2), "stratified samples"))

    def independent():
        estimate, exact = _occluded_light(48, 91, stratified=False)
        require(_slope_problem(impl, estimate, exact, (4, 16, 64, 256), (0, 1, 2), "independent samples"))

    def other():
        estimate, exact = _occluded_light(32, 92, size=0.9)
        require(_slope_problem(impl, estimate, exact, (9, 25, 100, 400, 900), (3, 5), "a larger occluder, 2 seeds"))
    return grade_parts((1, "stratified samples", stratified),
                       (1, "independent samples (another slope)", independent),
                       (1, "other counts, seeds and occluder", other))
