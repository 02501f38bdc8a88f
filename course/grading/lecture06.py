"""The checks of lecture 6's graded tasks (shadow maps): 6.1 light_space, 6.2 biased_lit, 6.3 pcf.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``; nothing here is public.

References: the three building blocks ``course.shadows.shadow_factor`` is made of, each called with the
student's signature: 6.1 ``course.shadows.light_space`` (``project_points`` with its two results side by
side, the lookup of pass 2), 6.2 ``course.shadows.biased_lit`` (the comparison with the two-part bias), 6.3
``course.shadows.pcf`` (the k×k filter; a neighbour outside the map is lit). ``_light_space_variants``,
``_lit_variants`` and ``_pcf_mistake`` give the typical mistakes' answers, to say what went wrong. A graded
function that reaches its reference, or another package function doing the task's work (``project_points``,
``shadow_factor`` ...), scores 0.
"""
from __future__ import annotations

import torch

from .helpers import _call, _diagnose, _ref, compare, generator, grade_parts, require, to_tensor
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


# --------------------------------------------------------------------------- 6.2 the biased comparison

def _biased_lit(z, stored, texel, tan_theta, bias, slope_bias):
    """The reference, ``course.shadows.biased_lit``: lit where ``not (z - total > stored)``, total = bias +
    slope_bias * texel * tan θ (so a stored +inf, an empty texel, is lit)."""
    return _ref("course.shadows", "biased_lit")(z, stored, texel, tan_theta, bias, slope_bias)


def _lit_variants(z, stored, texel, tan_theta, bias, slope_bias) -> list:
    return [(~(z > stored), "the bias is missing: compare z - (bias + slope_bias * texel * tan θ) with the stored "
             "depth"),
            (~(z + bias + slope_bias * texel * tan_theta > stored), "the bias is added: subtract it, moving the "
             "point toward the light"),
            (z - bias - slope_bias * texel * tan_theta < stored, "a point exactly at the stored depth (after the "
             "bias) is lit: shadowed only when z - bias > stored (use <=, not <)"),
            (~(z - bias - slope_bias * tan_theta > stored), "the slope term is in texels: multiply it by the "
             "texel's world width, slope_bias * texel * tan θ"),
            (~(z - slope_bias * texel * tan_theta > stored), "the constant bias is missing: add bias to the slope "
             "term"),
            (~(z - bias > stored), "the slope-scaled term is missing: the total bias is bias + slope_bias * texel "
             "* tan θ"),
            (z - bias - slope_bias * texel * tan_theta > stored, "that is 'shadowed': return True where the point "
             "is lit")]


def _run_lit(impl, args, what):
    name = f"biased_lit ({what})"
    got = to_tensor(_call(impl, *args), name)
    expected = _biased_lit(*args)
    if got.shape != expected.shape:
        require(f"{name}: return an (N,) bool tensor, shape {tuple(expected.shape)} expected, got {tuple(got.shape)}")
    if got.dtype != torch.bool:
        require(f"{name}: return a bool tensor (True where lit), got dtype {str(got.dtype).replace('torch.', '')}")
    if torch.equal(got, expected):
        return
    explanations = {e for alternative, e in _lit_variants(*args)
                    if torch.equal(got, alternative) and not torch.equal(expected, alternative)}
    if len(explanations) == 1:                                         # one mistake, and only one, gives this
        require(f"{name}: {explanations.pop()}")
    require(compare(got, expected, name=name))


def _lit_case(n, seed, dtype, bias=0.02, slope_bias=1.5):
    g = generator(seed)
    u = lambda: torch.rand(n, generator=g, dtype=torch.float64)          # noqa: E731
    stored = 2 + 2 * u()
    texel = 0.01 + 0.04 * u()
    tan_theta = 3 * u()
    z = stored + (u() - 0.5) * 4 * (bias + slope_bias * texel * tan_theta)   # around the threshold
    return tuple(x.to(dtype) for x in (z, stored, texel, tan_theta)) + (bias, slope_bias)


@task("6.2", "biased_lit", points=3, reference=("course.shadows", "biased_lit"))
def _check_biased_lit(impl):
    require(forbidden_call(impl, "biased_lit", [("course.shadows", "shadow_factor"),
                                                ("course.shadows", "biased_depth"), ("course.shadows", "pcf")]))

    def basic():
        _run_lit(impl, _lit_case(200, 71, torch.float64), "points near the threshold, bias 0.02, slope_bias 1.5")
        _run_lit(impl, _lit_case(100, 72, torch.float64, 0.0, 3.0), "bias 0, slope_bias 3")

    def edges():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)              # noqa: E731
        z = f64([1.0, 1.5, 2.0, 3.0, 0.5, 1.25, 1.1, 1.2])
        stored = f64([1.0, 1.0, float("inf"), 2.75, 1.0, 1.0, 1.0, 1.0])
        texel = f64([0.125, 0.125, 0.125, 0.125, 0.125, 0.125, 0.125, 0.125])
        tan = f64([0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5])
        _run_lit(impl, (z, stored, texel, tan, 0.25, 1.0), "exactly at the threshold, an empty texel (+inf), "
                 "bias 0.25, slope_bias 1")
        _run_lit(impl, (z, stored, texel, tan, 0.0, 0.0), "no bias at all: z <= stored is lit")

    def stress():
        _run_lit(impl, _lit_case(100, 73, torch.float32), "float32")
        z, stored, texel, tan, _, _ = _lit_case(100, 74, torch.float64, 1e-7, 0.5)
        _run_lit(impl, (z * 1e4, stored * 1e4, texel, tan, 1e-3, 0.5), "depths around 1e4, float64")
        empty = torch.zeros(0, dtype=torch.float64)
        got = to_tensor(_call(impl, empty, empty, empty, empty, 0.1, 1.0), "biased_lit (no points)")
        if got.shape != (0,):
            require(f"biased_lit (no points): return shape (0,), got {tuple(got.shape)}")

    return grade_parts((1, "near the threshold", basic), (1, "edge cases", edges), (1, "stress", stress))


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
