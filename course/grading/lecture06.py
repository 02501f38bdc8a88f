"""The checks of lecture 6's graded tasks (shadow maps): 6.1 light_space, 6.2 depth_bias, 6.3 pcf, 6.4 acne_bias.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``; nothing here is public.

References: 6.1 ``course.shadows.light_space`` (``project_points`` with its two results side by side, the
lookup of pass 2); 6.2 the two-part bias as ``shadow_factor`` computes it (the texel's world width, tan θ
from the normal and the direction to the light, clamped; ``_depth_bias`` here, which the task's reference
``course.shadows.biased_depth`` completes); 6.3 ``course.shadows.pcf`` (the k×k filter; a neighbour outside
the map is lit); 6.4, an analysis, ``_acne_bias`` here: the smallest constant bias that leaves every given
point fully lit under k×k PCF, found by the student's function on the grader's maps. ``_light_space_variants``,
``_bias_variants``, ``_pcf_mistake`` and ``_acne_variants`` give the typical mistakes' answers, to say what
went wrong. A graded function that reaches its reference, or another package function doing the task's work
(``project_points``, ``shadow_factor`` ...), scores 0.
"""
from __future__ import annotations

import math

import torch

from .helpers import _call, _close, _diagnose, _ref, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


# --------------------------------------------------------------------------------- 6.1 light space

def _light_space(points, K, R, t, orthographic):
    """The reference, ``course.shadows.light_space``: (N, 3) columns (x, y, depth)."""
    with torch.no_grad():
        return _ref("course.shadows", "light_space")(points, K, R, t, orthographic)


def _light_space_variants(points, K, R, t, orthographic) -> list:
    p = points.to(torch.float64)
    K, R, t = K.to(torch.float64), R.to(torch.float64), t.to(torch.float64)
    cam = p @ R.T + t
    z = cam[:, 2]
    ortho_xy = torch.cat([cam[:, :2], torch.ones_like(z)[:, None]], 1) @ K.T
    persp_xy = (cam / z[:, None]) @ K.T
    right = ortho_xy if orthographic else persp_xy
    wrong = persp_xy if orthographic else ortho_xy
    out = [(torch.cat([wrong[:, :2], z[:, None]], 1),
            "an orthographic light camera (a directional light) does not divide by depth: x = fx X + cx"
            if orthographic else "a perspective light camera (a spot or point light) divides by depth: "
            "x = fx X / Z + cx"),
           (torch.cat([right[:, :2].flip(-1), z[:, None]], 1),
            "x and y are swapped: return (x, y, depth), x the column"),
           (torch.cat([right[:, :2], cam.norm(dim=-1)[:, None]], 1),
            "the depth is the camera-space z (along the light's axis), not the distance to the light"),
           (torch.cat([right[:, :2], -z[:, None]], 1), "the depth is +z, positive in front of the camera"),
           (torch.cat([((torch.cat([(p @ R.T)[:, :2], torch.ones_like(z)[:, None]], 1) if orthographic
                         else (p @ R.T) / (p @ R.T)[:, 2:]) @ K.T)[:, :2], (p @ R.T)[:, 2:]], 1),
            "the translation t is missing: camera space is R X + t"),
           (torch.cat([right[:, :2] - K[:2, 2], z[:, None]], 1),
            "the principal point is missing: add (cx, cy) = (K[0, 2], K[1, 2])")]
    return out


def _run_light_space(impl, points, K, R, t, orthographic, what):
    name = f"light_space ({what})"
    got = _call(impl, points, K, R, t, orthographic)
    expected = _light_space(points, K, R, t, orthographic)
    g = to_tensor(got, name)
    if g.shape != expected.shape:
        require(f"{name}: return an (N, 3) tensor of (x, y, depth), shape {tuple(expected.shape)} expected, got "
                f"{tuple(g.shape)}")
    tol = {} if points.dtype == torch.float64 else dict(atol=1e-3, rtol=1e-4)
    require(_diagnose(g, expected, name, _light_space_variants(points, K, R, t, orthographic), check_dtype=True,
                      **tol))


def _cameras(dtype):
    from course.shading import DirectionalLight
    from course.shadows import SpotLight, light_camera
    bounds = (torch.tensor([0.2, 0.4, -0.1], dtype=dtype), 1.5)
    ortho = light_camera(DirectionalLight((0.5, -1.0, 0.3)), bounds, resolution=64)
    spot = light_camera(SpotLight((1.0, 3.0, 0.5), (-0.3, -1.0, -0.1), angle=70.0), bounds, resolution=48)
    return ortho, spot


def _points(n, seed, dtype, scale=1.2, center=(0.2, 0.4, -0.1)):
    g = generator(seed)
    p = (torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1) * scale + torch.tensor(center)
    return p.to(dtype)


@task("6.1", "light_space", points=3, reference=("course.shadows", "light_space"))
def _check_light_space(impl):
    require(forbidden_call(impl, "light_space", [("course.camera", "project_points"),
                                                  ("course.camera", "Camera.project"),
                                                  ("course.camera", "world_to_camera")]))

    def ortho():
        cam, _ = _cameras(torch.float32)
        _run_light_space(impl, _points(40, 61, torch.float32), cam.K, cam.R, cam.t, True,
                         "a directional light's orthographic camera, float32")

    def persp():
        _, cam = _cameras(torch.float64)
        _run_light_space(impl, _points(40, 62, torch.float64), cam.K, cam.R, cam.t, False,
                         "a spot light's perspective camera, float64")

    def stress():
        f64 = torch.float64
        K = torch.tensor([[90.0, 0.0, 20.5], [0.0, 70.0, 11.25], [0.0, 0.0, 1.0]], dtype=f64)  # fx != fy, off centre
        c, s = 0.6, 0.8
        R = torch.tensor([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]], dtype=f64)
        t = torch.tensor([0.3, -0.2, 5.0], dtype=f64)
        for orthographic in (True, False):
            _run_light_space(impl, _points(30, 63, f64, 2.0, (0.0, 0.0, 0.0)), K, R, t, orthographic,
                             f"an off-centre K with fx != fy, {'orthographic' if orthographic else 'perspective'}")
        far = _points(10, 64, f64, 1e3, (0.0, 0.0, 0.0)) + torch.tensor([1e4, -2e4, 3e4], dtype=f64)
        _run_light_space(impl, far, K, R, t + torch.tensor([0.0, 0.0, 1e5], dtype=f64), False,
                         "huge coordinates, float64")
        one = torch.tensor([[0.0, 0.0, 0.0]], dtype=f64)
        _run_light_space(impl, one, K, R, t, True, "one point")

    return grade_parts((1, "orthographic", ortho), (1, "perspective", persp), (1, "stress", stress))


# --------------------------------------------------------------------------- 6.2 the two-part bias

def _depth_bias(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope):
    """The reference: ``bias + slope_bias * texel * tan θ`` (N,) in z's dtype, texel = 1 / fx (orthographic) or
    z / fx (perspective), tan θ between the normal's line and the direction to the light, clamped to max_slope
    (``course.shadows``' slope term, as ``shadow_factor`` computes it)."""
    with torch.no_grad():
        tan = _ref("course.shadows.maps", "_tan_theta")(normals, to_light, float(max_slope))
        texel = torch.full_like(z, 1.0 / fx) if orthographic else z / fx
        return _ref("course.shadows", "biased_depth")(torch.zeros_like(z), texel, tan, bias, slope_bias).neg()


def _bias_variants(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope) -> list:
    z64, n, l = z.to(torch.float64), normals.to(torch.float64), to_light.to(torch.float64)
    dot = (n * l).sum(-1)
    norms = n.norm(dim=-1) * l.norm(dim=-1)
    cos = dot.abs() / norms
    sin = (1 - cos * cos).clamp_min(0).sqrt()
    texel = torch.full_like(z64, 1.0 / fx) if orthographic else z64 / fx
    tan = (sin / cos).clamp(max=max_slope)
    signed_cos = dot / norms
    signed_tan = torch.where(signed_cos != 0, (1 - signed_cos ** 2).clamp_min(0).sqrt() / signed_cos,
                             torch.full_like(z64, math.inf)).clamp(max=max_slope)
    raw_cos = dot.abs().clamp(max=1)
    raw_tan = ((1 - raw_cos ** 2).clamp_min(0).sqrt() / raw_cos).clamp(max=max_slope)
    total = lambda t=tan, w=texel, b=bias: b + slope_bias * w * t                            # noqa: E731
    other = z64 / fx if orthographic else torch.full_like(z64, 1.0 / fx)
    return [(total(t=sin / cos), "clamp tan θ to max_slope: at grazing light it has no bound"),
            (total(w=other), "an orthographic light's texel has the same world width everywhere, 1 / fx" if orthographic
             else "a perspective light's texel grows with depth: its world width at the point is z / fx"),
            (total(t=signed_tan), "a normal may point either way: use |n · l| for cos θ"),
            (total(t=raw_tan), "normalise: cos θ = |n · l| / (|n| |l|) (normals and directions need not be unit)"),
            (total(t=sin.clamp(max=max_slope)), "a surface tilted by θ changes depth by texel · tan θ across a "
             "texel: tan θ, not sin θ"),
            (total(b=0.0), "the constant bias is missing: the total is bias + slope_bias · texel · tan θ"),
            (bias + slope_bias * tan, "the slope term is in texels: multiply by the texel's world width at the point"),
            (z64 - total(), "return the total bias, not the biased depth z - bias")]


def _run_bias(impl, args, what):
    name = f"depth_bias ({what})"
    z = args[0]
    got = to_tensor(_call(impl, *args), name)
    expected = _depth_bias(*args)
    if got.shape != expected.shape:
        require(f"{name}: return one bias per point, shape {tuple(expected.shape)} expected, got {tuple(got.shape)}")
    tol = {} if z.dtype == torch.float64 else dict(atol=1e-5, rtol=1e-4)
    require(_diagnose(got, expected, name, _bias_variants(*args), check_dtype=True, **tol))


def _bias_case(n, seed, dtype, orthographic, fx, spread=1.2, flip=False, scale=False):
    g = generator(seed)
    u = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)        # noqa: E731
    to_light = torch.tensor([0.3, 1.0, -0.2], dtype=torch.float64) + 0.2 * (u(n, 3) - 0.5)
    normals = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64) + spread * (u(n, 3) - 0.5)
    if flip:
        normals[::3] *= -1                                                  # seen from the other side
    if scale:
        normals = normals * (0.2 + 3 * u(n, 1))
        to_light = to_light * (0.5 + 4 * u(n, 1))
    z = 2 + 3 * u(n)
    return tuple(x.to(dtype) for x in (z, normals, to_light)) + (fx, orthographic)


@task("6.2", "depth_bias", points=3, reference=("course.shadows", "biased_depth"))
def _check_depth_bias(impl):
    require(forbidden_call(impl, "depth_bias", [("course.shadows", "shadow_factor"),
                                                ("course.shadows.maps", "_tan_theta")]))

    def orthographic():
        _run_bias(impl, _bias_case(60, 71, torch.float64, True, 40.0) + (0.01, 1.5, 10.0),
                  "a directional light, fx = 40, bias 0.01, slope_bias 1.5, max_slope 10")

    def perspective():
        _run_bias(impl, _bias_case(60, 72, torch.float64, False, 128.0, flip=True, scale=True) + (0.002, 2.0, 5.0),
                  "a spot light, fx = 128, normals of any length and either side, bias 0.002, slope_bias 2")

    def stress():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        normals = f64([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.05, 0.0], [0.0, -2.0, 0.0], [1.0, 1.0, 0.0]])
        to_light = f64([[0.0, 1.0, 0.0]] * 5)
        _run_bias(impl, (f64([3.0, 3.0, 3.0, 3.0, 3.0]), normals, to_light, 64.0, True, 0.0, 1.0, 10.0),
                  "grazing light (n · l = 0), steeper than max_slope, facing, from below, 45°")
        _run_bias(impl, _bias_case(40, 73, torch.float32, False, 90.0, spread=3.0) + (0.005, 1.5, 4.0), "float32")
        empty, none = torch.zeros(0, dtype=torch.float64), torch.zeros(0, 3, dtype=torch.float64)
        got = to_tensor(_call(impl, empty, none, none, 64.0, True, 0.01, 1.5, 10.0), "depth_bias (no points)")
        if got.shape != (0,):
            require(f"depth_bias (no points): return shape (0,), got {tuple(got.shape)}")

    return grade_parts((1, "orthographic", orthographic), (1, "perspective", perspective), (1, "stress", stress))


# ------------------------------------------------------------------------- 6.3 percentage-closer filtering

def _texels(coords):
    return coords[:, 1].floor().long(), coords[:, 0].floor().long()        # (row, col) of the texel holding (x, y)


def _pcf(depth_map, coords, depths, k):
    """The reference, ``course.shadows.pcf``: the fraction of the k×k texels around each point's texel whose
    stored depth is not nearer than the point's; a neighbour outside the map is lit. (N,) in depth_map's dtype."""
    with torch.no_grad():
        return _ref("course.shadows", "pcf")(depth_map, coords, depths, k)


def _pcf_mistake(depth_map, coords, depths, k, outside="lit", divide="all", offsets=None, swap=False,
                 texel="floor", filter_depths=False):
    """PCF written out in float64, with switches that give the typical mistakes' answers (``_pcf_variants``);
    with the defaults it is the reference's formula: ``mean(not (depth > stored))``, outside the map lit."""
    H, W = depth_map.shape
    if texel == "floor":
        row, col = _texels(coords)
    else:
        row, col = coords[:, 1].round().long(), coords[:, 0].round().long()
    if swap:
        row, col = col, row
    r = (k - 1) // 2
    offs = list(range(-r, r + 1)) if offsets is None else offsets
    lit = torch.zeros(depths.shape, dtype=torch.float64)
    count = torch.zeros(depths.shape, dtype=torch.float64)
    stored_sum = torch.zeros(depths.shape, dtype=torch.float64)
    d = depths.to(torch.float64)
    for dy in offs:
        for dx in offs:
            rr, cc = row + dy, col + dx
            valid = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            stored = depth_map.to(torch.float64)[rr.clamp(0, H - 1), cc.clamp(0, W - 1)]
            ok = ~(d > stored)
            if outside == "lit":
                lit += (ok | ~valid).to(torch.float64)
            else:
                lit += (ok & valid).to(torch.float64)
            count += valid.to(torch.float64)
            stored_sum += torch.where(valid, stored, torch.zeros_like(stored))
    if filter_depths:
        return (~(d > stored_sum / count.clamp_min(1))).to(depth_map.dtype)
    n = float(len(offs) ** 2)
    return (lit / (count.clamp_min(1) if divide == "valid" else n)).to(depth_map.dtype)


def _pcf_variants(depth_map, coords, depths, k) -> list:
    ref = _pcf(depth_map, coords, depths, k)
    mistake = lambda **how: _pcf_mistake(depth_map, coords, depths, k, **how)      # noqa: E731
    return [(mistake(outside="shadow"), "a neighbour outside the map counts as lit "
             "(the map cannot see it): add 1 for it, as for a lit texel"),
            (mistake(outside="shadow", divide="valid"), "divide by k * k, every "
             "neighbour counted, the ones outside the map as lit"),
            (mistake(filter_depths=True), "PCF filters the comparisons, not the depths: "
             "compare the point with each of the k × k stored depths and average the 0/1 results"),
            (mistake(swap=True), "rows and columns are swapped: coords are (x, y), the "
             "texel is row floor(y), column floor(x)"),
            (mistake(texel="round"), "the texel holding (x, y) is (floor(y), floor(x)): "
             "texel (i, j) covers [j, j + 1) × [i, i + 1)"),
            (mistake(offsets=list(range(k))), "the window is centred on the point's "
             "texel: offsets -(k - 1) / 2 … (k - 1) / 2"),
            (1 - ref, "that is the shadowed fraction: return the lit fraction (1 where nothing is nearer)")]


def _run_pcf(impl, depth_map, coords, depths, k, what):
    name = f"pcf (k = {k}, {what})"
    got = to_tensor(_call(impl, depth_map, coords, depths, k), name)
    expected = _pcf(depth_map, coords, depths, k)
    require(_diagnose(got, expected, name, _pcf_variants(depth_map, coords, depths, k), check_dtype=True,
                      atol=1e-6, rtol=1e-6))


def _pcf_case(H, W, n, seed, dtype):
    g = generator(seed)
    depth = 1 + torch.rand(H, W, generator=g, dtype=torch.float64)
    depth[torch.rand(H, W, generator=g) < 0.15] = float("inf")                 # empty texels
    coords = torch.rand(n, 2, generator=g, dtype=torch.float64) * torch.tensor([W - 1e-6, H - 1e-6])
    depths = 1 + torch.rand(n, generator=g, dtype=torch.float64)
    return depth.to(dtype), coords.to(dtype), depths.to(dtype)


@task("6.3", "pcf", points=3, reference=("course.shadows", "pcf"))
def _check_pcf(impl):
    require(forbidden_call(impl, "pcf", [("course.shadows", "shadow_factor")]))

    def one_and_three():
        depth, coords, depths = _pcf_case(9, 12, 60, 81, torch.float64)
        for k in (1, 3):
            _run_pcf(impl, depth, coords, depths, k, "a random 9 × 12 map, float64")

    def five_and_borders():
        depth, coords, depths = _pcf_case(7, 6, 50, 82, torch.float64)
        _run_pcf(impl, depth, coords, depths, 5, "a random 7 × 6 map, float64")
        edge = torch.tensor([[0.0, 0.0], [5.999, 6.999], [0.5, 3.5], [3.0, 0.25], [5.5, 0.0]], dtype=torch.float64)
        deep = torch.full((5,), 1.9, dtype=torch.float64)
        _run_pcf(impl, depth, edge, deep, 3, "points on the map's borders and corners")
        _run_pcf(impl, depth, edge, deep, 7, "a window wider than the map")

    def stress():
        depth, coords, depths = _pcf_case(16, 16, 80, 83, torch.float32)
        _run_pcf(impl, depth, coords, depths, 3, "float32")
        flat = torch.full((8, 8), 2.0, dtype=torch.float64)
        c = torch.tensor([[3.5, 4.5], [0.5, 0.5]], dtype=torch.float64)
        _run_pcf(impl, flat, c, torch.tensor([2.0, 2.0], dtype=torch.float64), 3, "a point exactly at the stored "
                 "depth (lit)")
        big = torch.full((64, 64), float("inf"), dtype=torch.float64)
        big[:, :32] = 1.0                                                      # a straight shadow edge
        x = torch.linspace(28.0, 36.0, 33, dtype=torch.float64)
        edge = torch.stack([x, torch.full_like(x, 20.5)], 1)
        _run_pcf(impl, big, edge, torch.full_like(x, 1.5), 5, "the ramp across a straight edge")

    return grade_parts((1, "k = 1 and 3", one_and_three), (1, "k = 5, borders, a wide window", five_and_borders),
                       (1, "stress", stress))


# ------------------------------------------------------------------ 6.4 how much bias acne needs (an analysis)

def _acne_bias(depth_map, coords, depths, k, *, window="centred", swap=False, own_texel=False, reduce="max",
               clamp=True):
    """The reference of task 6.4: the smallest constant b >= 0 with ``pcf(depth_map, coords, depths - b, k) == 1``
    at every point, a 0-d tensor in depth_map's dtype: the largest ``depth - stored`` over the points and the
    k×k texels of their windows inside the map (a neighbour outside is lit whatever b is), or 0. The keyword
    switches give the typical mistakes' answers."""
    H, W = depth_map.shape
    d = torch.as_tensor(depths).to(depth_map.dtype)
    row, col = coords[:, 1].floor().long(), coords[:, 0].floor().long()
    if swap:
        row, col = col, row
    r = (k - 1) // 2
    offsets = [0] if own_texel else (list(range(-r, r + 1)) if window == "centred" else list(range(k)))
    need = torch.full(d.shape, -math.inf, dtype=depth_map.dtype)
    for dy in offsets:
        for dx in offsets:
            rr, cc = row + dy, col + dx
            inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            stored = depth_map[rr.clamp(0, H - 1), cc.clamp(0, W - 1)]
            need = torch.maximum(need, torch.where(inside, d - stored, torch.full_like(need, -math.inf)))
    if reduce == "mean":
        finite = need[torch.isfinite(need)]
        worst = finite.mean() if finite.numel() else torch.zeros((), dtype=depth_map.dtype)
    else:
        worst = need.max() if need.numel() else torch.tensor(-math.inf, dtype=depth_map.dtype)
    if clamp:
        return worst.clamp_min(0)
    return worst if torch.isfinite(worst) else torch.zeros((), dtype=depth_map.dtype)


def _acne_variants(depth_map, coords, depths, k) -> list:
    v = lambda **how: _acne_bias(depth_map, coords, depths, k, **how)        # noqa: E731
    return [(v(own_texel=True), "PCF compares the point with every texel of its k × k window: the bias must "
             "cover the farthest of them, not only the point's own texel"),
            (v(swap=True), "rows and columns are swapped: coords are (x, y), the texel is row floor(y), column "
             "floor(x)"),
            (v(window="corner"), "the window is centred on the point's texel: offsets -(k - 1) / 2 … (k - 1) / 2"),
            (v(reduce="mean"), "the bias must light every point: take the largest need, not the mean"),
            (v(clamp=False), "the bias is never negative: when every point is already lit, the smallest bias is 0")]


def _run_acne(impl, depth_map, coords, depths, k, what):
    name = f"acne_bias (k = {k}, {what})"
    got = to_tensor(_call(impl, depth_map, coords, depths, k), name)
    expected = _acne_bias(depth_map, coords, depths, k)
    if got.dim() != 0:
        require(f"{name}: return one number (a 0-d tensor), the bias for all points, got shape {tuple(got.shape)}")
    tol = {} if depth_map.dtype == torch.float64 else dict(atol=1e-5, rtol=1e-5)
    variants = _acne_variants(depth_map, coords, depths, k)
    telling = [(v, e) for v, e in variants if sum(_close(v, w) for w, _ in variants) == 1]   # one mistake gives it
    require(_diagnose(got, expected, name, telling, check_dtype=True, **tol))


def _plane_case(light_dir, resolution, n, seed):
    """A 4 × 4 ground under a tilted directional light, its shadow map, and n seeded points on it in light space."""
    from course.models import plane
    from course.shading import DirectionalLight
    from course.shadows import light_space, shadow_map
    sm = shadow_map(plane(4.0, dtype=torch.float64), DirectionalLight(light_dir), resolution)
    g = generator(seed)
    p = torch.rand(n, 2, generator=g, dtype=torch.float64) * 3.6 - 1.8
    pts = torch.stack([p[:, 0], torch.zeros(n, dtype=torch.float64), p[:, 1]], 1)
    xyz = light_space(pts, sm.camera)
    return sm.depth[0], xyz[:, :2], xyz[:, 2]


@task("6.4", "acne_bias", points=4, reference=("course.grading.lecture06", "_acne_bias"))
def _check_acne_bias(impl):
    def one():
        depth, coords, depths = _pcf_case(9, 12, 60, 91, torch.float64)
        _run_acne(impl, depth, coords, depths, 1, "a random 9 × 12 map, float64")

    def windows():
        depth, coords, depths = _pcf_case(10, 8, 50, 92, torch.float64)
        for k in (3, 5):
            _run_acne(impl, depth, coords, depths, k, "a random 10 × 8 map with empty texels, float64")

    def planes():
        for light, res, seed in (((1.0, -1.0, 0.3), 64, 93), ((0.2, -1.0, -0.7), 48, 94)):
            depth, coords, depths = _plane_case(light, res, 400, seed)
            for k in (1, 3, 5):
                _run_acne(impl, depth, coords, depths, k, f"a ground under a light along {light}, {res} texels")

    def stress():
        depth, coords, depths = _pcf_case(6, 7, 30, 95, torch.float64)
        _run_acne(impl, depth, coords, depths - 5.0, 3, "every point already lit")
        edge = torch.tensor([[0.0, 0.0], [6.999, 5.999], [0.5, 3.5], [3.0, 0.25]], dtype=torch.float64)
        _run_acne(impl, depth, edge, torch.full((4,), 1.9, dtype=torch.float64), 3, "points on the map's borders")
        _run_acne(impl, depth, edge, torch.full((4,), 1.9, dtype=torch.float64), 9, "a window wider than the map")
        d32, c32, z32 = _pcf_case(8, 8, 40, 96, torch.float32)
        _run_acne(impl, d32, c32, z32, 3, "float32")
        none = torch.zeros(0, 2, dtype=torch.float64)
        _run_acne(impl, depth, none, torch.zeros(0, dtype=torch.float64), 3, "no points")

    return grade_parts((1, "k = 1", one), (1, "k = 3 and 5", windows), (1, "tilted grounds", planes),
                       (1, "lit already, borders, float32, no points", stress))
