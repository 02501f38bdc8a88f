"""The checks of lecture 7's graded tasks (ray tracing): 7.1 ray_triangle, 7.2 ray_aabb, 7.3 shadow_ray.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``; nothing here is public.

References: 7.1 is ``course.raytrace.intersect_triangles`` with the hits behind the origin (t <= 0) removed;
7.2 is ``course.raytrace.ray_box`` (``_slab_reference``, in float64); 7.3 is brute force over every
triangle with ``intersect_triangles`` (``_shadow_reference``), the same answer as ``course.raytrace.visible``
on these scenes. A function that reaches a package function doing the task's work scores 0 and is told so.
"""
from __future__ import annotations

import math

import torch

from .helpers import _call, _ref, _unpack, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS

EPS = 1e-6                       # 7.3: hits with t <= EPS or t >= 1 - EPS do not block (t = 1 at the light)


def _mismatch(got: torch.Tensor, expected: torch.Tensor, where: torch.Tensor) -> bool:
    return bool(((got != expected) & where).any())


# ---------------------------------------------------------------------------------- 7.1 ray–triangle

def _triangle_reference(o, d, tris):
    t, bary, hit = _ref("course.raytrace", "intersect_triangles")(o, d, tris)
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


@task("7.1", "ray_triangle", points=3, reference=("course.intersect", "intersect_triangles"))
def _check_ray_triangle(impl):
    forbidden = forbidden_call(impl, "ray_triangle", [("course.intersect", "moller_trumbore"),
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


@task("7.2", "ray_aabb", points=3, reference=("course.intersect", "ray_box"))
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
    return grade_parts((1, "random rays and boxes", random),
                       (1, "negative direction components", negative),
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


@task("7.3", "shadow_ray", points=3, reference=("course.raytrace", "visible"))
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
                                "points at the occluders' corners", on_surface=torch.ones(v.shape[0], dtype=torch.bool)))
    return grade_parts((1, "points under an occluder", above),
                       (1, "occluders beyond the light and behind the point", beyond),
                       (1, "points on surfaces and at vertices (self-shadowing), float64", surface))
