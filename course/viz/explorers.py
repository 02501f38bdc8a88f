"""One interactive explorer per lecture 03-12: the lecture's central trade-off on sliders.

A notebook cell is one call, e.g. ``viz.fill_rule_explorer()``. Each explorer is a thin wrapper around a pure
``draw_*`` function that draws one figure for one set of slider values and returns a dict of the numbers it
shows, computed in float64, with its ``"line"``: one sentence rounded so that it reads the same on every CPU.
The explorer prints the line of its defaults once below the widget (nbval compares it) and sends the picture
of its defaults along as a PNG, which a viewer without widgets shows in place of the sliders.

Costly scenes (a fit's snapshots, a landscape, a texture synthesis) are computed once, on first use, and kept
(``functools.cache``); each redraw at its default size takes well under 200 ms on a laptop CPU afterwards
(``python -m course bench explorers``). Where a redraw costs more, the explorer redraws on release and greys
its controls out while it draws.
"""
from __future__ import annotations

import math
from functools import cache

import matplotlib
import matplotlib.collections
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np
import torch

from .core import explorer, show_image, signed_image
from .raster import plot_raster

__all__ = ["fill_rule_explorer", "supersampling_explorer", "shadow_map_explorer", "bvh_explorer",
           "area_light_explorer", "soft_explorer", "edge_explorer", "finite_difference_explorer",
           "edge_sampling_explorer", "fit_explorer", "loss_landscape_explorer", "style_weight_explorer",
           "shadow_light_explorer", "penumbra_explorer", "gaussian_explorer", "draw_fill_rule", "draw_supersampling", "draw_shadow_map", "draw_bvh",
           "draw_area_light", "draw_soft", "draw_edge", "draw_finite_difference", "draw_edge_sampling",
           "draw_fit", "draw_loss_landscape", "draw_style_weight", "draw_shadow_light", "draw_penumbra", "draw_gaussian", "EXPLORERS"]

F64 = torch.float64
FIGURE_SCALE = 1.0          # the figures are 5-9 inches wide: at matplotlib's 100 dpi they already fill a notebook


def _r4(x) -> float:
    return round(float(x), 4) + 0.0                                         # 4 decimals, never "-0.0"


def _sig(x) -> str:
    return f"{float(x):.3g}"                                                # 3 significant digits


def _check_range(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise ValueError(f"{name} must be a number in [{lo}, {hi}], got {value!r}")
    return value


def _check_choice(name, value, options):
    if value not in options:
        raise ValueError(f"{name} must be one of {list(options)}, got {value!r}")
    return value


def _show(draw):
    """Run ``draw`` in an explorer with its controls (``EXPLORERS``), then print the line of its defaults below
    the widget."""
    (_, _, sliders, continuous), = [entry for entry in EXPLORERS.values() if entry[1] is draw]
    first = {}

    def redraw(**values):
        out = draw(**values)
        first.setdefault("line", out["line"])

    redraw.continuous_update = continuous
    explorer(redraw, figure_scale=FIGURE_SCALE, still=True, **sliders)
    print(first["line"])


def _screen_camera(width, height):
    """An orthographic camera that maps world (x, y, z) to pixel (x, y) at depth z (lectures 05, 08, 09)."""
    from ..camera import Camera
    eye = torch.eye(3, dtype=F64)
    return Camera(eye, eye, torch.zeros(3, dtype=F64), width, height, near=0.1, far=10.0, orthographic=True)


def _screen_mesh(triangles):
    """Separate triangles (F, 3, 2) in pixel coordinates at depth 1, as a float64 Mesh."""
    from ..mesh import Mesh
    t = torch.as_tensor(triangles, dtype=F64)
    t = torch.cat([t, torch.ones(*t.shape[:-1], 1, dtype=F64)], -1)
    return Mesh(t.reshape(-1, 3), torch.arange(3 * t.shape[0]).reshape(-1, 3))


# ------------------------------------------------------------------------------------------------ lecture 03
FILL_SIZE = 8
_COUNTS = matplotlib.colors.ListedColormap(["white", "#9ecae1", "#d62728"])   # 0, 1 and 2 triangles
_FACES = matplotlib.colors.ListedColormap(["white", "#fdd0a2", "#fcbba1", "#c7e9c0"])   # none, A, B, C (outlines')


def draw_fill_rule(x: float = 5.5, y: float = 5.5, depth: float = 0.5) -> dict:
    """Two triangles A and B share the edge from (1.5, 1.5) to the vertex (x, y) you drag; a third, C, lies
    over them at ``depth``, while A and B lie on a plane tilted from depth 0.2 (left) to 0.84 (right).

    Left: how many of A and B cover each pixel centre. Drag the vertex so the shared edge runs through pixel
    centres (x = y, in steps of 0.5): the top-left rule gives every centre on it to exactly one triangle, so no
    count reads 2 (drawn twice: wrong under blending) and none reads 0 inside (a crack). Right: the z-buffer's
    answer, the nearest of A, B and C at each centre: raise ``depth`` and C sinks behind the tilted plane from
    the left. Returns the counts and the line.
    """
    from ..raster import inside_triangle, zbuffer_resolve
    x, y = _check_range("x", x, 0.0, FILL_SIZE), _check_range("y", y, 0.0, FILL_SIZE)
    depth = _check_range("depth", depth, 0.0, 1.0)
    n = FILL_SIZE
    p0, p1, p2 = (1.5, 1.5), (7.5, 2.0), (2.0, 7.5)
    tris = torch.tensor([[p0, p1, (x, y)], [p0, (x, y), p2], [(0.6, 7.4), (7.6, 3.2), (7.4, 7.6)]], dtype=F64)
    jj, ii = torch.meshgrid(torch.arange(n, dtype=F64) + 0.5, torch.arange(n, dtype=F64) + 0.5, indexing="xy")
    centres = torch.stack([jj, ii], -1).reshape(-1, 2)                      # (P, 2) pixel centres, row-major
    hit = torch.stack([inside_triangle(t, centres) for t in tris])          # (3, P)
    plane = 0.2 + 0.08 * centres[:, 0]                                      # A and B: tilted along x
    depths = torch.stack([plane, plane, torch.full_like(plane, depth)])     # (3, P)
    face, pix = hit.nonzero(as_tuple=True)                                  # every fragment
    face_map, _ = zbuffer_resolve(pix, depths[face, pix], face, n * n)
    counts = (hit[0].long() + hit[1].long()).view(n, n)
    both, covered = int((counts == 2).sum()), int((counts > 0).sum())
    overlap = hit[2] & (hit[0] | hit[1])
    c_front = int((overlap & (face_map == 2)).sum())
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 4.2))
    plot_raster(counts, tris[:2], ax=axes[0], cmap=_COUNTS, vmin=-0.5, vmax=2.5,
                title=f"A + B per centre: white 0, blue 1, red 2 ({both})")
    plot_raster(face_map.view(n, n).double(), tris, ax=axes[1], cmap=_FACES, vmin=-1.5, vmax=2.5,
                title=f"z-buffer: nearest of A, B, C (C at {depth:g})")
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.02, top=0.9, wspace=0.08)
    line = (f"vertex ({x:g}, {y:g}): A or B at {covered} centres, both at {both}; "
            f"C in front at {c_front} of {int(overlap.sum())} shared centres")
    return dict(covered=covered, both=both, c_front=c_front, overlap=int(overlap.sum()), line=line)


def fill_rule_explorer() -> None:
    """Lecture 03: drag a vertex across pixel centres and watch the fill rule and the z-buffer answer."""
    _show(draw_fill_rule)


# ------------------------------------------------------------------------------------------------ lecture 05
@cache
def _aa_scene(shape: str):
    """(mesh, camera, face colours, exact coverage) of the sliver or the teapot's silhouette, float64."""
    from ..antialias import exact_coverage
    from ..mesh import Mesh
    from ..models import teapot
    from ..render import frame_camera
    if shape == "sliver":
        mesh, camera = _screen_mesh([[[0.5, 1.2], [31.5, 8.1], [31.5, 8.5]]]), _screen_camera(32, 10)
    else:
        pot = teapot(3, dtype=F64)
        mesh = Mesh(pot.verts, pot.faces)
        camera = frame_camera(mesh, width=40, height=28)
        camera = camera.to(dtype=F64)
    colors = torch.ones(mesh.faces.shape[0], 3, dtype=F64)                  # white: the image is coverage
    return mesh, camera, colors, exact_coverage(mesh, camera, colors)[..., 0]


def draw_supersampling(k: int = 2, jitter: bool = False, shape: str = "sliver") -> dict:
    """k × k samples per pixel, on a regular grid or jittered (one random sample per stratum), against the
    exact coverage of each pixel (``coverage.exact_coverage``), on a 0.4-px sliver or the teapot's outline.

    The coverage panels share one colour scale from 0 (dark) to 1 (yellow), so the sliver's faint pixels
    (at most 0.36 covered) stand out from the empty ones. Look at the error image (estimate - exact; red:
    too bright, blue: too dark, its colour bar in coverage units): with a regular grid the sliver breaks into
    pieces at small k (8 pieces at 2 × 2, one from 4 × 4 on), and the error sits in runs along the edges
    (aliasing); jitter turns the runs into noise of the same size. The RMS error falls roughly like k^-1.5
    for both shapes, as on lecture 05's spheres (edges are what is left).
    The line printed under the figure is the one the explorer cell prints for its defaults.
    """
    from ..antialias import supersample
    k = int(_check_range("k", k, 1, 16))
    shape = _check_choice("shape", shape, ("sliver", "teapot"))
    if not isinstance(jitter, bool):
        raise ValueError(f"jitter must be True or False, got {jitter!r}")
    mesh, camera, colors, exact = _aa_scene(shape)
    image = supersample(mesh, camera, colors, k, jitter=jitter)[..., 0]     # (H, W) coverage estimate
    error = image - exact
    rmse = float(error.pow(2).mean().sqrt())
    line = f"{shape}, {k} x {k} {'jittered' if jitter else 'regular'}: RMS error against exact coverage {_r4(rmse)}"
    sliver = shape == "sliver"                                              # 32 x 10 px: one panel a row
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 6.4)) if sliver else plt.subplots(1, 3, figsize=(10.5, 3.1))
    name = f"{k} × {k} = {k * k} samples, {'jittered' if jitter else 'regular'}"
    for ax, values, title in [(axes[0], image, name), (axes[1], exact, "exact coverage")]:
        show_image(values, ax=ax, cmap="viridis", vmin=0, vmax=1)
        ax.set_title(title, fontsize=10)
        fig.colorbar(ax.images[0], ax=ax, fraction=0.046, pad=0.03, label="coverage")
    signed_image(error, ax=axes[2])
    axes[2].set_title(f"error, RMS {_sig(rmse)}", fontsize=10)
    fig.colorbar(axes[2].images[0], ax=axes[2], fraction=0.046, pad=0.03, label="estimate - exact")
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.tight_layout(rect=(0, 0.05 if sliver else 0.08, 1, 1))
    return dict(rmse=rmse, line=line)


def supersampling_explorer() -> None:
    """Lecture 05: supersampling's k, jitter on or off, and its error against exact coverage."""
    _show(draw_supersampling)


# ------------------------------------------------------------------------------------------------ lecture 06
SHADOW_GRID = 48


@cache
def _wall_scene():
    """A floor (4 x 4 at y = 0) and a wall (x = 0.5, 1 high, 1 wide) under light travelling 45° toward +x:
    the true shadow runs on the floor from x = 0.5 to 1.5, |z| < 0.5. Ground points (N, 3), float64."""
    from ..mesh import Mesh
    from ..models import plane
    from ..shading import DirectionalLight
    floor = plane(4.0, dtype=F64)
    wall = Mesh(torch.tensor([[0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [0.5, 1.0, 0.5], [0.5, 1.0, -0.5]], dtype=F64),
                torch.tensor([[0, 1, 2], [0, 2, 3]]))
    light = DirectionalLight((math.sin(math.pi / 4), -math.cos(math.pi / 4), 0.0))
    gx = torch.linspace(-0.2, 1.9, SHADOW_GRID, dtype=F64)
    gz = torch.linspace(-1.0, 1.0, SHADOW_GRID, dtype=F64)
    X, Z = torch.meshgrid(gx, gz, indexing="xy")                            # (G, G): rows along z
    points = torch.stack([X, torch.zeros_like(X), Z], -1).reshape(-1, 3)
    truth = ((X > 0.5) & (X < 1.5) & (Z.abs() < 0.5)).reshape(-1)
    return [floor, wall], light, points, truth, (float(gx[0]), float(gx[-1]), float(gz[-1]), float(gz[0]))


def draw_shadow_map(resolution: int = 64, bias: float = 0.0, slope_bias: float = 0.0, pcf: int = 1) -> dict:
    """The floor seen from above, lit (white) or in the wall's shadow (black), by a shadow map of
    ``resolution`` texels a side, a constant ``bias`` (texels) and a slope-scaled ``slope_bias`` (texels ×
    tan θ), filtered by k × k percentage-closer filtering. The dashed box is the true shadow.

    With no bias the lit floor breaks into stripes of false shadow (acne: the floor shadows itself, the
    depth of a texel's centre against the points across it). A little bias cures it; too much pushes the
    shadow off the wall's foot (peter-panning: a lit gap at x = 0.5). Higher resolution shrinks both; PCF
    softens the staircase of the shadow's edge.
    """
    from ..shadows.maps import shadow_factor, shadow_map
    resolution = int(_check_range("resolution", resolution, 8, 2048))
    bias, slope_bias = _check_range("bias", bias, 0.0, 50.0), _check_range("slope_bias", slope_bias, 0.0, 50.0)
    pcf = _check_choice("pcf", pcf, (1, 3, 5, 7, 9))
    meshes, light, points, truth, extent = _wall_scene()
    sm = shadow_map(meshes, light, resolution)
    texel = 1.0 / float(sm.camera.K[0, 0])
    normals = torch.tensor([0.0, 1.0, 0.0], dtype=F64).expand_as(points)
    lit = shadow_factor(points, normals, sm, bias=bias * texel, slope_bias=slope_bias, pcf=pcf)   # (N,)
    acne = float((lit[~truth] < 1).double().mean())                         # false shadow on the lit floor
    near_foot = truth & (points[:, 0] < 0.6)                                # the first 0.1 behind the wall
    gap = float((lit[near_foot] > 0).double().mean())                       # light leaking under the wall
    fig, ax = plt.subplots(figsize=(5.2, 5.0))
    ax.imshow(lit.view(SHADOW_GRID, SHADOW_GRID).numpy(), cmap="gray", vmin=0, vmax=1, extent=extent,
              interpolation="nearest")
    ax.plot([0.5, 1.5, 1.5, 0.5, 0.5], [-0.5, -0.5, 0.5, 0.5, -0.5], "--", color="tab:orange", lw=1.2)
    ax.plot([0.5, 0.5], [-0.5, 0.5], color="tab:red", lw=3, label="the wall's foot")
    ax.set_xlabel("x (light travels toward +x)"), ax.set_ylabel("z")
    ax.set_title(f"{resolution}² map, bias {bias:g} + slope {slope_bias:g}, PCF {pcf}\n"
                 f"acne {_sig(acne)}, lit at the foot {_sig(gap)}", fontsize=10)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    line = (f"{resolution} texels, bias {bias:g}, slope {slope_bias:g}, pcf {pcf}: lit floor in false shadow "
            f"{_r4(acne)}, shadow lit at the wall's foot {_r4(gap)}")
    return dict(acne=acne, gap=gap, line=line)


def shadow_map_explorer() -> None:
    """Lecture 06: shadow-map resolution, constant and slope bias and PCF: acne and peter-panning."""
    _show(draw_shadow_map)


# ------------------------------------------------------------------------------------------------ lecture 07
RT_SIZE = 48
BVH_DEPTH = 14                                                              # the deepest level of its BVH


@cache
def _rt_world():
    """Lecture 07's world (a floor, a ball, a ring), its BVH, camera rays and the depth of every BVH node."""
    from ..bvh import BVH
    from ..camera import Camera
    from ..mesh import Mesh, join_meshes
    from ..models import icosphere, plane, torus
    ball, ring = icosphere(2, radius=0.6, dtype=F64), torus(0.5, 0.18, 24, 12, dtype=F64)
    world = join_meshes([plane(4.0, 4, dtype=F64), Mesh(ball.verts + torch.tensor([-0.5, 0.6, 0.2], dtype=F64),
                                                         ball.faces),
                         Mesh(ring.verts + torch.tensor([0.7, 0.18, -0.4], dtype=F64), ring.faces)])
    camera = Camera.look_at((0.0, 3.2, 4.0), (0.0, 0.1, -0.1), fov_y=45, width=RT_SIZE, height=RT_SIZE).to(dtype=F64)
    bvh = BVH(world)
    M = bvh.boxes.shape[0]
    parent = torch.full((M,), -1, dtype=torch.long)
    inner = (bvh.left >= 0).nonzero().squeeze(1)
    parent[bvh.left[inner]], parent[bvh.left[inner] + 1] = inner, inner
    level = torch.zeros(M, dtype=torch.long)
    for node in range(1, M):                                                # breadth-first: parents come first
        level[node] = level[parent[node]] + 1
    origins, directions = camera.rays()
    origins, directions = origins.reshape(-1, 3).to(F64), directions.reshape(-1, 3).to(F64)
    hits = bvh.intersect(origins, directions)
    boxes, triangles = _tests_per_ray(bvh, parent, level, origins, directions)
    return world, camera, bvh, level, origins, directions, hits, boxes, triangles


def _tests_per_ray(bvh, parent, level, origins, directions):
    """(boxes, triangles) tested per ray by a traversal that enters every box the ray meets (no pruning by
    the closest hit so far): a node's box is tested when the ray entered its parent; a leaf's triangles when
    the ray entered the leaf. Vectorised over rays and nodes, (N,) each."""
    inv = 1.0 / directions                                                  # (N, 3), ±inf where d = 0
    lo = (bvh.boxes[None, :, 0] - origins[:, None]) * inv[:, None]          # (N, M, 3)
    hi = (bvh.boxes[None, :, 1] - origins[:, None]) * inv[:, None]
    t0 = torch.minimum(lo, hi).nan_to_num(-math.inf).amax(-1)
    t1 = torch.maximum(lo, hi).nan_to_num(math.inf).amin(-1)
    meets = (t0 <= t1) & (t1 >= 0)                                          # (N, M)
    entered = meets.clone()
    for depth in range(1, int(level.max()) + 1):                            # a child only inside its parent
        at = (level == depth).nonzero().squeeze(1)
        entered[:, at] &= entered[:, parent[at]]
    tested = torch.ones_like(entered)
    tested[:, 1:] = entered[:, parent[1:]]
    boxes = tested.sum(1)
    triangles = (entered.double() * bvh.count.double()).sum(1)
    return boxes, triangles


def draw_bvh(level: int = 3, heat: str = "boxes") -> dict:
    """The world of lecture 07 with the boxes of one BVH ``level`` drawn over it (each box's outline on
    screen), and a heat map of the work per ray: the boxes, or the triangles, a ray tests.

    Level 0 is one box around everything; each level splits every box in two. Rays that graze many boxes
    (the ring, the ball's rim, the floor behind them) do the most work; rays into empty floor test a few
    boxes and a handful of triangles out of 928, which is the whole point of the tree.
    """
    heat = _check_choice("heat", heat, ("boxes", "triangles"))
    world, camera, bvh, lv, _, _, _, boxes, triangles = _rt_world()
    level = int(_check_range("level", level, 0, int(lv.max())))
    work = (boxes if heat == "boxes" else triangles).double().view(RT_SIZE, RT_SIZE)
    fig, ax = plt.subplots(figsize=(5.6, 4.8))
    im = ax.imshow(work.numpy(), cmap="magma", extent=(0, RT_SIZE, RT_SIZE, 0), interpolation="nearest")
    plt.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label=f"{heat} tested per ray")
    nodes = (lv == level).nonzero().squeeze(1)
    corners = torch.stack(torch.meshgrid(*(torch.arange(2),) * 3, indexing="ij"), -1).reshape(8, 3)
    pts = bvh.boxes[nodes][:, corners, torch.arange(3)]                     # (B, 8, 3) each box's corners
    xy, z = camera.project(pts.reshape(-1, 3))
    xy, front = xy.reshape(-1, 8, 2), (z.reshape(-1, 8) > 0).all(1)        # boxes wholly in front of the eye
    lo, hi = xy.amin(1)[front].numpy(), xy.amax(1)[front].numpy()          # (B', 2) each box's outline on screen
    outlines = np.stack([lo, np.c_[hi[:, 0], lo[:, 1]], hi, np.c_[lo[:, 0], hi[:, 1]], lo], 1)   # (B', 5, 2)
    ax.add_collection(matplotlib.collections.LineCollection(outlines, colors=[f"C{k % 10}" for k in
                                                                              range(len(outlines))], lw=1.0))
    ax.set_xlim(0, RT_SIZE), ax.set_ylim(RT_SIZE, 0), ax.set_xticks([]), ax.set_yticks([])
    ax.set_title(f"BVH level {level} ({len(nodes)} boxes); mean {heat} per ray {_sig(work.mean())}", fontsize=10)
    fig.subplots_adjust(left=0.02, right=0.9, bottom=0.02, top=0.92)
    line = (f"level {level}: {len(nodes)} boxes; per ray on average {_r4(boxes.double().mean())} boxes and "
            f"{_r4(triangles.mean())} triangles tested of {world.faces.shape[0]}")
    return dict(boxes=float(boxes.double().mean()), triangles=float(triangles.mean()), nodes=len(nodes), line=line)


def bvh_explorer() -> None:
    """Lecture 07: the BVH level by level over the image, and the boxes or triangles each ray tests."""
    _show(draw_bvh)


_NO_SURFACE = "#9ecae1"                                                     # pale blue: camera rays that hit nothing


def draw_area_light(size: float = 1.0, samples: int = 4) -> dict:
    """Soft shadows of a square area light of side ``size`` above the world of lecture 07, estimated with
    ``samples`` × ``samples`` stratified shadow rays per pixel.

    A point light (size 0) casts hard shadows; the larger the light, the wider the penumbra, where the
    fraction of the light a point sees falls from 1 to 0. Few samples give a noisy penumbra (steps of
    1 / samples²); more samples smooth it at a proportional cost. White is fully lit, black the umbra (no
    shadow ray reaches the light), pale blue the pixels whose camera ray meets no surface; the sphere and the
    torus that cast the shadows are painted in solid colours (lecture 07's ``lit_fraction_grid``), so they do
    not melt into the lit, white floor.
    """
    from ..raytrace import rectangle_light_samples, visible
    size = _check_range("size", size, 0.0, 3.0)
    samples = int(_check_range("samples", samples, 1, 16))
    world, camera, bvh, _, origins, directions, hits, _, _ = _rt_world()
    seen = hits.hit
    points = origins[seen] + hits.t[seen, None] * directions[seen]          # (P, 3) world points seen
    corners = world.verts[world.faces[hits.face_id[seen]]]
    normals = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = normals * torch.sign((normals * -directions[seen]).sum(1, keepdim=True))   # toward the camera
    centre = torch.tensor([0.3, 3.0, 0.4], dtype=F64)
    half = max(size, 1e-6) / 2
    ex, ez = torch.tensor([2 * half, 0.0, 0.0], dtype=F64), torch.tensor([0.0, 0.0, 2 * half], dtype=F64)
    light = rectangle_light_samples(centre - ex / 2 - ez / 2, ex, ez, points.shape[0], samples, seed=0)
    frac = visible(points, light, bvh, normals=normals).double()           # (P,) in [0, 1]
    image = torch.full((RT_SIZE * RT_SIZE,), math.nan, dtype=F64)           # NaN where a camera ray hits nothing
    image[seen] = frac
    penumbra = float(((frac > 0) & (frac < 1)).double().mean())
    rays = f"{samples} x {samples} = {samples * samples} shadow ray{'s' if samples > 1 else ''} per pixel"
    line = (f"light {size:g} wide, {rays}: mean visibility {_r4(frac.mean())}, penumbra {_r4(penumbra)} of the "
            f"points seen")
    fig, ax = plt.subplots(figsize=(5.6, 5.0))
    from .raytrace import CASTER_COLOURS
    rgb = np.repeat(np.nan_to_num(image.numpy(), nan=0.0)[:, None], 3, axis=1)   # (H W, 3) grey: the fraction
    rgb[~seen.numpy()] = matplotlib.colors.to_rgb(_NO_SURFACE)
    part = torch.bucketize(hits.face_id, torch.tensor([32, 352]), right=True).numpy()   # 0 floor, 1 ball, 2 ring
    for k in (1, 2):
        rgb[seen.numpy() & (part == k)] = matplotlib.colors.to_rgb(CASTER_COLOURS[k - 1])
    show_image(rgb.reshape(RT_SIZE, RT_SIZE, 3), ax=ax, srgb=False)
    bar = fig.colorbar(matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0, 1), "gray"), ax=ax,
                       fraction=0.046, pad=0.03, ticks=[0, 0.5, 1])
    bar.ax.set_yticklabels(["0: umbra", "0.5", "1: fully lit"])
    bar.set_label("fraction of the light a point sees (floor)")
    handles = [matplotlib.patches.Patch(color=colour, label=name)
               for colour, name in zip((_NO_SURFACE, *CASTER_COLOURS[:2]), ("no surface", "sphere", "torus"))]
    ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.9)
    ax.set_title(f"light {size:g} wide, {rays.replace(' x ', ' × ')}\npenumbra (0 < fraction < 1): "
                 f"{_sig(penumbra)} of the points seen", fontsize=10)
    fig.text(0.5, 0.01, line.replace(": ", ":\n", 1), ha="center", va="bottom", fontsize=9)   # the printed line
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return dict(mean=float(frac.mean()), penumbra=penumbra, line=line)


def area_light_explorer() -> None:
    """Lecture 07: an area light's size and the shadow rays per pixel: penumbra width against noise."""
    _show(draw_area_light)


# ------------------------------------------------------------------------------------------------ lecture 08
SOFT_SIZE = 24
SOFT_FLOOR = 1e-6           # |d image / d x| below this is the forward difference's round-off (~1e-11), not a change


@cache
def _soft_scene():
    tris = [[[3.0, 4.0], [20.0, 6.0], [8.0, 20.0]], [[10.0, 9.0], [22.0, 12.0], [14.0, 22.0]]]
    mesh = _screen_mesh(tris)
    mesh.verts[3:, 2] = 2.0                                                 # the second triangle lies behind
    colors = torch.tensor([[0.9, 0.3, 0.2], [0.2, 0.4, 0.9]], dtype=F64)
    return mesh, _screen_camera(SOFT_SIZE, SOFT_SIZE), colors


def draw_soft(log_sigma: float = -2.5, log_gamma: float = -2.0) -> dict:
    """Soft rasterization (lecture 08) of two overlapping triangles, σ = 10^log_sigma (how far a triangle's
    edge blurs: about √σ in normalised device units, 2 across the image, so σ = 1e-3 is ~0.4 px) and
    γ = 10^log_gamma (how softly the nearer triangle hides the farther), and beside it the gradient image:
    d image / d x of the front triangle's vertices moved right together (red: brighter).

    A sharp σ gives an image close to the hard one, and a gradient only in a thin band along the edges: most
    pixels tell the optimiser nothing. A wide σ blurs the image but spreads the gradient far from the edges.
    A large γ lets the back triangle show through the front one; a small γ at fixed σ lets the front triangle
    outweigh the white background past its edges, by sqrt(σ_px (z - ε) / γ) pixels (the line's border; the
    largest derivatives then sit on that border, not on the edges). The gradient is a forward difference in
    float64 of an image that is smooth in the vertices (step 1e-5 px: its error is far below what shows);
    a pixel "moves" when it changes by more than ``SOFT_FLOOR`` per px, far above the difference's round-off.
    Its colour scale ends at the 90th percentile of the pixels that move (the colour bar's arrows: the
    largest pixels are drawn at its ends), so the band along the edges shows beside a few large pixels.
    """
    from ..mesh import Mesh
    from ..soft import soft_rasterize
    log_sigma, log_gamma = _check_range("log_sigma", log_sigma, -5.0, -1.0), _check_range("log_gamma", log_gamma,
                                                                                           -4.0, 0.0)
    mesh, camera, colors = _soft_scene()
    sigma, gamma, h = 10.0 ** log_sigma, 10.0 ** log_gamma, 1e-5

    def image(shift):
        verts = mesh.verts.clone()
        verts[:3, 0] += shift
        return soft_rasterize(Mesh(verts, mesh.faces), camera, mode="color", sigma=sigma, gamma=gamma,
                              face_colors=colors, background=1.0, cull_backfaces=False)   # (H, W, 3)

    soft = image(0.0)
    d_image = ((image(h) - soft) / h).sum(-1)                               # (H, W) summed over RGB
    size = d_image.abs()
    moved = size > SOFT_FLOOR                                               # above the difference's round-off
    reach = float(moved.double().mean())
    # the colour scale ends at the 90th percentile of the pixels that move, so that a few pixels of a large
    # derivative do not wash out the rest; the pixels beyond it are drawn at the end of the scale
    lim = float(torch.quantile(size[moved], 0.9)) if moved.any() else 1.0
    # how far the front triangle outweighs the background past its edges (lecture 08, section 4):
    # D e^{z/γ} > e^{ε/γ} where d² < σ (z - ε) / γ, d in NDC units (2 across the image)
    z_front = (camera.far - 1.0) / (camera.far - camera.near)              # orthographic: linear in depth 1
    border = math.sqrt(sigma * SOFT_SIZE ** 2 / 4 * (z_front - 1e-3) / gamma)   # pixels
    line = (f"sigma {sigma:.3g}, gamma {gamma:.3g}: image mean {_r4(soft.mean())}, gradient sum "
            f"{_r4(d_image.sum())}, nonzero at {_r4(reach)} of the pixels; the front triangle outweighs "
            f"the background up to {_sig(border)} px past its edges")
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 5.0))
    show_image(soft, f"soft image, σ = {sigma:.3g}, γ = {gamma:.3g}", ax=axes[0])
    show_image(d_image, ax=axes[1], cmap="RdBu_r", vmin=-lim, vmax=lim)
    axes[1].set_title(f"d image / d x (front triangle): {int(moved.sum())} pixels move,\n"
                      f"{int((size > lim).sum())} beyond ±{_sig(lim)} drawn at the ends", fontsize=10)
    fig.colorbar(axes[1].images[0], ax=axes[1], fraction=0.046, pad=0.03, extend="both",
                 label="per px of shift (red: brighter)")
    fig.text(0.5, 0.01, line.replace("; ", ";\n"), ha="center", va="bottom", fontsize=9)   # the printed line
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    return dict(mean=float(soft.mean()), gradient=float(d_image.sum()), reach=reach, border=border, line=line)


def soft_explorer() -> None:
    """Lecture 08: σ and γ, the soft image and its gradient image side by side."""
    _show(draw_soft)


# ------------------------------------------------------------------------------------------------ lecture 09
def _segment_in_pixel(p, d):
    """Length of the line p + s d (d unit) inside the unit square [0, 1]²."""
    s0, s1 = -math.inf, math.inf
    for a in range(2):
        if abs(d[a]) < 1e-15:
            if not 0.0 <= p[a] <= 1.0:
                return 0.0
            continue
        u, v = (0.0 - p[a]) / d[a], (1.0 - p[a]) / d[a]
        s0, s1 = max(s0, min(u, v)), min(s1, max(u, v))
    return max(0.0, s1 - s0)


def draw_edge(offset: float = 0.5, angle: float = 20.0) -> dict:
    """An edge, tilted ``angle`` degrees from the vertical, moved right across one pixel: the pixel's
    coverage (the area left of the edge) against the edge's position, and its derivative, the boundary term.

    The derivative of the area is the length of the edge inside the pixel times how fast it moves along its
    normal (cos of the tilt), the Reynolds transport theorem in one pixel; it is zero when the edge misses the
    pixel and largest when it crosses it through the middle. Autograd through the box-filtered area gives the
    same number; a one-sample-per-pixel image would have derivative 0 everywhere, and a jump. The covered part
    of the pixel is shaded; the line printed under the figure is the one the explorer cell prints for its
    defaults.
    """
    from ..coverage import halfplane_pixel_area
    offset, angle = _check_range("offset", offset, -1.0, 2.0), _check_range("angle", angle, -60.0, 60.0)
    th = math.radians(angle)
    n = (math.cos(th), math.sin(th))                                        # the edge's normal, pointing right

    def area(x0):                                        # the pixel's area left of the edge through (x0, 0.5)
        x0 = torch.as_tensor(x0, dtype=F64)
        line = torch.stack([-n[0] + 0 * x0, -n[1] + 0 * x0, n[0] * x0 + n[1] * 0.5])   # n·p <= n·(x0, 0.5)
        return halfplane_pixel_area(line, 0, 0)

    x = torch.tensor(offset, dtype=F64, requires_grad=True)
    a = area(x)
    autograd = torch.autograd.grad(a, x)[0] if a.requires_grad else torch.zeros((), dtype=F64)   # missed: 0
    a = a.detach()
    boundary = _segment_in_pixel((offset, 0.5), (-math.sin(th), math.cos(th))) * n[0]
    xs, ys = np.linspace(-1.0, 2.0, 121), np.linspace(0.0, 1.0, 401)[:, None]   # rows of the pixel, for the curve
    curve = np.clip(xs + math.tan(th) * (0.5 - ys), 0.0, 1.0).mean(0)     # ∫ width left of the edge dy
    line = (f"offset {offset:g}, tilt {angle:g} deg: coverage {_r4(a)}, boundary term {_r4(boundary)}, "
            f"autograd {_r4(autograd)}")
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.0))
    ax = axes[0]
    u = (np.arange(200) + 0.5) / 200                                        # the pixel, 200 x 200 points
    covered = (n[0] * (u[None, :] - offset) + n[1] * (u[:, None] - 0.5)) <= 0   # left of the edge
    ax.imshow(np.where(covered, 1.0, np.nan), extent=(0, 1, 1, 0), cmap="Blues", vmin=0, vmax=2)
    ax.add_patch(plt.Rectangle((0, 0), 1, 1, fill=False, lw=1.5))
    s = np.linspace(-2, 2, 2)
    ax.plot(offset - s * math.sin(th), 0.5 + s * math.cos(th), color="tab:red", label="the edge")
    ax.set_xlim(-1, 2), ax.set_ylim(2, -1), ax.set_aspect("equal"), ax.set_xticks([]), ax.set_yticks([])
    ax.set_title(f"the pixel: coverage {float(a):.3f}", fontsize=10)
    ax.legend(handles=[ax.lines[0], matplotlib.patches.Patch(color=matplotlib.colormaps["Blues"](0.5), label="covered")],
              loc="lower right", fontsize=8)
    axes[1].plot(xs, curve, label="coverage")
    axes[1].plot(xs, np.gradient(curve, xs), "--", label="d coverage / d offset")
    axes[1].plot([offset], [boundary], "o", color="tab:red", label=f"boundary term {boundary:.3f}")
    axes[1].set_xlabel("edge offset (px)"), axes[1].legend(fontsize=8)
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.subplots_adjust(left=0.04, right=0.98, bottom=0.2, top=0.92, wspace=0.25)
    return dict(coverage=float(a), boundary=boundary, autograd=float(autograd), line=line)


def edge_explorer() -> None:
    """Lecture 09: an edge moved across a pixel, the coverage and its derivative, the boundary term."""
    _show(draw_edge)


@cache
def _gradient_scene():
    """One triangle over an 8 x 8 image, seeded weights: the loss L = Σ weights ⊙ image of lecture 09."""
    mesh = _screen_mesh([[[1.3, 1.7], [6.6, 2.9], [2.8, 6.4]]])
    colors = torch.tensor([[0.8, 0.6, 0.3]], dtype=F64)
    weights = torch.rand(8, 8, 3, generator=torch.Generator().manual_seed(0), dtype=F64)
    return mesh, _screen_camera(8, 8), colors, weights


@cache
def _fd_estimate(log_step: float, dtype) -> float:
    """The central difference (L(x + h) - L(x - h)) / 2h, x the first vertex's x, h = 10^log_step, computed in
    ``dtype`` (each step computed once)."""
    from ..coverage import exact_coverage
    from ..mesh import Mesh
    mesh, camera, colors, weights = _gradient_scene()
    h = 10.0 ** log_step

    def loss(shift):
        verts = mesh.verts.to(dtype).clone()
        verts[0, 0] += shift
        image = exact_coverage(Mesh(verts, mesh.faces), camera.to(dtype=dtype), colors.to(dtype))
        return float((weights.to(dtype) * image).sum())

    return (loss(h) - loss(-h)) / (2 * h)


def _fd_error(log_step: float, dtype) -> float:
    """The relative error of ``_fd_estimate`` against the exact dL/dx."""
    return abs(_fd_estimate(log_step, dtype) - _fd_exact()) / abs(_fd_exact())


@cache
def _fd_exact() -> float:
    from ..visibility import image_gradient
    mesh, camera, colors, weights = _gradient_scene()
    return float(image_gradient(mesh, camera, colors, weights, method="exact")[0, 0])


@cache
def _fd_curve():
    """The error at every decade of the step, 1e-12 ... 1e-1, in float64 and float32 (computed once)."""
    logs = np.arange(-12.0, -0.5, 1.0)
    return logs, {name: [_fd_error(e, dtype) for e in logs] for name, dtype in (("float64", F64),
                                                                                ("float32", torch.float32))}


def draw_finite_difference(log_step: float = -5.0) -> dict:
    """The central finite difference of ``L = Σ weights ⊙ image`` w.r.t. a triangle's vertex (x), step h =
    10^log_step px, against the exact gradient, in float64 and float32 (the curves, at every decade, are
    computed once; the red dots at h are computed as you move the slider).

    Too large a step and the difference quotient averages over the changing slope (error ~ h², and worse
    where an edge crosses a pixel corner within h); too small and rounding wins (error ~ ε / h). The best step
    sits in between, at (3 δL / |L‴|)^(1/3) with δL the rounding error of L: here the step is in pixels and
    L‴ is of order one, so it lands near ε^(1/3), at 1e-5 in float64 (error 6e-11) and 1e-2 in float32 (error
    2e-5, over 1e5 times float64's best). (Lecture 09's sphere moves a vertex in world units, 13 pixels
    each: its L‴ is large and its best float64 step smaller, 1e-6.) The line printed under the figure is the
    one the explorer cell prints for its defaults.
    """
    log_step = _check_range("log_step", log_step, -12.0, -1.0)
    logs, curves = _fd_curve()
    now = {"float64": _fd_error(log_step, F64), "float32": _fd_error(log_step, torch.float32)}
    fig, ax = plt.subplots(figsize=(5.6, 3.8))
    for k, (name, err) in enumerate(curves.items()):
        ax.loglog(10.0 ** logs, np.maximum(err, 1e-17), marker=".", color=f"C{k}", label=name)
        ax.plot([10.0 ** log_step], [max(now[name], 1e-17)], "o", color="tab:red")
    ax.set_xlabel("step h (px)"), ax.set_ylabel("relative error"), ax.legend(fontsize=8)
    ax.set_title(f"h = 1e{log_step:g}: error {_sig(now['float64'])} (float64), {_sig(now['float32'])} (float32)",
                 fontsize=10)
    line = (f"step 1e{log_step:g}: central difference {_r4(_fd_estimate(log_step, F64))} in float64, "
            f"exact {_r4(_fd_exact())}")
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return dict(float64=now["float64"], float32=now["float32"], line=line)


def finite_difference_explorer() -> None:
    """Lecture 09: the finite-difference step against its error, truncation against rounding."""
    _show(draw_finite_difference)


EDGE_RUNS = 8


@cache
def _edge_runs(n: int) -> np.ndarray:
    """dL/dx of vertex 0 by edge sampling with n samples, seeds 0 ... EDGE_RUNS - 1 (each n computed once)."""
    from ..visibility import image_gradient
    mesh, camera, colors, weights = _gradient_scene()
    return np.array([float(image_gradient(mesh, camera, colors, weights, method="edge_sampling", samples=n,
                                          seed=s)[0, 0]) for s in range(EDGE_RUNS)])


def draw_edge_sampling(log_samples: float = 2.0) -> dict:
    """Edge sampling's estimate of dL/dx of one vertex with n = 10^log_samples samples on the edges, over 8 seeds
    (each n computed once): each run's estimate (dots) and their spread, against the exact gradient (the line).

    The estimate is unbiased: the runs scatter around the exact value at every n, and their spread falls
    like 1/√n (ten times the samples, about a third of the spread). The line printed under the figure is the
    one the explorer cell prints for its defaults.
    """
    log_samples = _check_range("log_samples", log_samples, 1.0, 3.5)
    n = int(round(10.0 ** log_samples))
    exact = _fd_exact()
    runs = _edge_runs(n)
    spread = float(runs.std())
    fig, ax = plt.subplots(figsize=(5.6, 3.2))
    ax.plot(runs, np.zeros_like(runs) + np.linspace(-0.2, 0.2, EDGE_RUNS), "o", alpha=0.7, label="one run each")
    ax.axvline(exact, color="tab:red", label=f"exact {exact:.4f}")
    ax.axvspan(runs.mean() - spread, runs.mean() + spread, color="tab:blue", alpha=0.15, label="mean ± spread")
    ax.set_ylim(-1, 1), ax.set_yticks([]), ax.set_xlabel("dL / dx of vertex 0")
    ax.set_xlim(exact - 1.2, exact + 1.2)
    ax.set_title(f"{n} edge samples, {EDGE_RUNS} seeds: spread {_sig(spread)}", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    line = f"{n} samples: exact {_r4(exact)}, mean of {EDGE_RUNS} runs {_r4(runs.mean())}, spread {_sig(spread)}"
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return dict(exact=exact, mean=float(runs.mean()), spread=spread, line=line)


def edge_sampling_explorer() -> None:
    """Lecture 09: edge sampling's samples against the spread of its estimates."""
    _show(draw_edge_sampling)


# ------------------------------------------------------------------------------------------------ lecture 10
FIT_STEPS = 20
SIGMAS = [1e-5, 1e-4, 1e-3]


@cache
def _pose_problem():
    """Lecture 10's camera fit reduced to one angle: the teapot seen by the reference camera orbited by φ about
    world +y; the target is φ = 0, the start 30°. Returns (mesh, colours, reference camera, target image)."""
    from ..inverse.pose import camera_problem
    from ..models import teapot
    mesh, colors, reference, _, target = camera_problem(teapot(3, dtype=F64), size=32)
    return mesh, colors, reference, target


def _orbit_render(phi, sigma):
    """The soft image (32, 32, 3) from the reference camera orbited by φ radians about world +y."""
    from ..camera import Camera, axis_angle_to_matrix
    from ..soft import soft_rasterize
    mesh, colors, ref, _ = _pose_problem()
    phi = torch.as_tensor(phi, dtype=F64)
    R_orbit = axis_angle_to_matrix(torch.stack([phi * 0, phi, phi * 0]))    # world rotation about +y
    camera = Camera(ref.K, ref.R @ R_orbit.T, ref.t, 32, 32, ref.near, ref.far)
    return soft_rasterize(mesh, camera, mode="color", sigma=sigma, gamma=1e-2, face_colors=colors, background=0.0)


@cache
def _fit_snapshots(sigma: float = 1e-4):
    """Adam on φ from 30°, ``FIT_STEPS`` steps: the angle, loss and image at every step."""
    target = _pose_problem()[3]
    phi = torch.tensor(math.radians(30.0), dtype=F64, requires_grad=True)
    opt = torch.optim.Adam([phi], lr=0.04)
    snaps = []
    for _ in range(FIT_STEPS + 1):
        image = _orbit_render(phi, sigma)
        loss = ((image - target) ** 2).mean()
        snaps.append((math.degrees(float(phi.detach())), float(loss.detach()), image.detach()))
        opt.zero_grad()
        loss.backward()
        opt.step()
    return snaps


def draw_fit(step: int = FIT_STEPS) -> dict:
    """A camera fit scrubbed step by step (the snapshots are computed once): the soft image at ``step``, the
    target, and the loss so far. The pose is one angle φ about the vertical, 30° off at the start; Adam follows
    the soft rasterizer's gradient (σ = 1e-4) back toward 0°. Its momentum carries φ past the answer: the loss
    is lowest at step 17 (φ = 0.2°) and rises again as φ overshoots to -3.3° at step 20 (the dot marks the
    lowest loss so far). The line printed under the figure is the one the explorer cell prints for its defaults.
    """
    step = int(_check_range("step", step, 0, FIT_STEPS))
    snaps = _fit_snapshots()
    phi, loss, image = snaps[step]
    losses = [s[1] * 1e3 for s in snaps[:step + 1]]                         # in units of 1e-3
    best = int(np.argmin(losses))
    line = f"step {step}: angle {phi:.2f} deg, loss {_sig(loss)}"
    fig, axes = plt.subplots(1, 3, figsize=(10.0, 3.6))
    show_image(image, f"step {step}: φ = {phi:.1f}°", ax=axes[0])
    show_image(_pose_problem()[3], "target (φ = 0°)", ax=axes[1])
    axes[2].plot(losses, marker=".")                                        # linear: no log-tick text to typeset
    axes[2].plot([best], [losses[best]], "o", color="tab:red", label=f"lowest so far: step {best}")
    axes[2].set_ylim(0, 1.05e3 * max(s[1] for s in snaps)), axes[2].legend(fontsize=8, loc="upper right")
    axes[2].set_xlim(0, FIT_STEPS), axes[2].set_xlabel("step"), axes[2].set_ylabel("loss (× 1e-3)")
    axes[2].set_title("L2 loss", fontsize=10)
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.2, top=0.9, wspace=0.25)
    return dict(phi=phi, loss=loss, line=line)


def fit_explorer() -> None:
    """Lecture 10: a fit's snapshots on a slider (precomputed on first use, about a second)."""
    _fit_snapshots()
    _show(draw_fit)


LANDSCAPE_STEP = 3.0        # degrees between the samples of a landscape, as lecture 10's whole-orbit curve


@cache
def _landscape(sigma: float):
    degrees = np.arange(-90.0, 90.0 + LANDSCAPE_STEP / 2, LANDSCAPE_STEP)
    target = _pose_problem()[3]
    with torch.no_grad():
        loss = [float(((_orbit_render(math.radians(d), sigma) - target) ** 2).mean()) for d in degrees]
    return degrees, np.array(loss)


def draw_loss_landscape(sigma: float = 1e-4) -> dict:
    """The loss of the camera fit along the pose angle φ (from -90° to 90° every 3°, the target at 0°),
    rendered soft with ``sigma`` (each curve is computed once), and where a walk downhill along the curve from
    the fit's start (30°) ends.

    At σ = 1e-5 and 1e-4 the soft image is nearly the hard one: the lowest point is at the answer, and the
    answer's valley reaches the start (the walk from 30° ends at 0°); the other valleys lie 60° or more from
    the start (-33° and 87° at σ = 1e-5, -57° at 1e-4). At σ = 1e-3 the blurred teapot matches the sharp target nowhere: the lowest point has moved to
    12°, the valley is shallower, and it has small bumps on the way (the walk from 30° stops at once). A 3°
    grid, like lecture 10's whole-orbit curve, is far too coarse to show the steps of the hard loss (lecture
    10's close-up samples every 0.01°). The line printed under the figure is the one the explorer cell prints
    for its defaults.
    """
    sigma = _check_choice("sigma", sigma, SIGMAS)
    degrees, loss = _landscape(sigma)
    i0, i30, low = int(np.argmin(np.abs(degrees))), int(np.argmin(np.abs(degrees - 30.0))), int(np.argmin(loss))
    end = i30
    while True:                                                             # downhill, one grid step at a time
        nxt = min((k for k in (end - 1, end + 1) if 0 <= k < len(loss)), key=lambda k: loss[k])
        if loss[nxt] >= loss[end]:
            break
        end = nxt
    line = (f"sigma {sigma:g}: lowest at {degrees[low]:g} deg, loss at 0 deg {_sig(loss[i0])}, at 30 deg "
            f"{_sig(loss[i30])}; downhill from 30 deg ends at {degrees[end]:g} deg")
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(degrees, loss * 1e3, marker=".", label=f"σ = {sigma:g}")
    ax.axvline(0.0, color="0.6", ls=":", label="the answer")
    ax.axvline(30.0, color="tab:green", ls=":", label="the fit's start")
    a, b = sorted((i30, end))
    ax.plot(degrees[a:b + 1], loss[a:b + 1] * 1e3, color="tab:red", lw=2.5, alpha=0.6,
            label=f"downhill from 30°: ends at {degrees[end]:g}°")
    ax.plot([degrees[low]], [loss[low] * 1e3], "v", color="k", label=f"lowest: {degrees[low]:g}°")
    ax.set_xlabel("pose angle φ (degrees)"), ax.set_ylabel("L2 loss (× 1e-3)"), ax.legend(fontsize=8)
    ax.set_title(f"loss along φ, σ = {sigma:g}", fontsize=10)
    fig.text(0.5, 0.01, line.replace("; ", ";\n"), ha="center", va="bottom", fontsize=9)   # the printed line
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return dict(lowest=float(degrees[low]), loss0=float(loss[i0]), loss30=float(loss[i30]),
                end=float(degrees[end]), line=line)


def loss_landscape_explorer() -> None:
    """Lecture 10: the loss along a pose angle, for the soft rasterizer's σ."""
    _show(draw_loss_landscape)


# ------------------------------------------------------------------------------------------------ lecture 11
STYLE_WEIGHTS = [0.0, 0.01, 0.03, 0.1, 1.0, 10.0]
STYLE_SIZE = 32
STYLE_STEPS = 100


@cache
def _style_run(weight: float):
    """The image nearest a content image (a checker) in L2 plus ``weight`` × the style loss of stripes:
    STYLE_STEPS Adam steps (lr 0.1) on its logits from the content, float64. Enough steps that each weight
    reaches its own balance of the two terms (after 40, every weight from 1 up gave the same image)."""
    from ..models import checker_texture
    from ..style import RandomFeatures, stripes, style_loss
    net = RandomFeatures(sizes=(3, 5), channels=16, scales=2, seed=0, dtype=F64)
    style = stripes(STYLE_SIZE, period=6.0, dtype=F64)
    content = checker_texture(STYLE_SIZE, 4, dtype=F64)
    target = [g.detach() for g in net(style)]
    logit = torch.logit(content.clamp(0.02, 0.98)).clone().requires_grad_(True)
    opt = torch.optim.Adam([logit], lr=0.1)
    for _ in range(STYLE_STEPS):
        image = torch.sigmoid(logit)
        loss = ((image - content) ** 2).mean() + weight * style_loss(net(image), target)
        opt.zero_grad()
        loss.backward()
        opt.step()
    image = torch.sigmoid(logit).detach()
    return content, style, image, float(((image - content) ** 2).mean()), float(style_loss(net(image), target))


def draw_style_weight(weight: float = 0.1) -> dict:
    """Style transfer's one knob: the weight of the style loss against the content loss. The result starts
    at the content (a checker) and takes 100 Adam steps on its pixels (each weight is computed once); its
    content error and style loss are printed above it.

    At weight 0 nothing changes; from 0.01 stripes show through the squares, at 0.1 both are there, and from 1
    the stripes cover the checker (its squares still tint them); the content error rises as the style loss
    falls. Adam's steps are about lr long whatever the loss's scale, so once the style term dominates a larger
    weight changes the result less: from 1 to 10 the style loss falls 1.7-fold and the content error rises
    1.24-fold, against 10-fold and 17-fold from 0.01 to 0.1. Images are sRGB-encoded for the screen, as every
    figure.
    """
    weight = _check_choice("weight", weight, STYLE_WEIGHTS)
    content, style, image, content_err, style_err = _style_run(weight)
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 4.0))
    show_image(content, "content (a checker)", ax=axes[0])
    show_image(style, "style (stripes)", ax=axes[1])
    show_image(image, f"style weight {weight:g}", ax=axes[2])
    axes[2].set_xlabel(f"content error {_sig(content_err)}, style loss {_sig(style_err)}")
    fig.tight_layout()
    line = f"style weight {weight:g}: content error {_sig(content_err)}, style loss {_sig(style_err)}"
    return dict(content=content_err, style=style_err, line=line)


def style_weight_explorer() -> None:
    """Lecture 11: the style weight against the content (precomputed per weight on first use); below it, every
    weight's content error and style loss."""
    _show(draw_style_weight)
    print("every weight (100 Adam steps each):")
    for weight in STYLE_WEIGHTS:
        *_, content_err, style_err = _style_run(weight)
        print(f"  style weight {weight:<4g}: content error {_sig(content_err)}, style loss {_sig(style_err)}")


# ------------------------------------------------------------------------------------------------ lecture 12
SHADOW_SIZE = 48                                                            # pixels a side, as lecture 12's section 1


@cache
def _shadow_problem():
    from ..shadows.gradients import shadow_scene
    return shadow_scene("floater", SHADOW_SIZE)


def draw_shadow_light(azimuth: float = 30.0, elevation: float = 60.0) -> dict:
    """The exact shadowed image (lecture 12) of a triangle floating over a floor, lit from ``azimuth`` and
    ``elevation`` (degrees), and beside it its gradient image: d image / d azimuth, summed over RGB, per degree
    (red: the pixel brightens as the azimuth grows, blue: it darkens; a colour bar gives the scale).

    The gradient lives on the shadow's edges only (inside and outside the shadow nothing changes), and it is
    exact: the image is the area of the lit part of each pixel, a smooth function of the light between the
    moments when a shadow edge crosses a vertex. Lower the light and the shadow stretches; its gradient grows.
    The image is shown as the lecture shows its images, linear values without sRGB encoding; the line printed
    under the figure is the one the explorer cell prints for its defaults.
    """
    from ..shadows.gradients import shadowed_coverage
    azimuth, elevation = _check_range("azimuth", azimuth, -180.0, 180.0), _check_range("elevation", elevation,
                                                                                       15.0, 89.0)
    mesh, camera, colors, _ = _shadow_problem()

    def light(az):
        a, e = math.radians(az), math.radians(elevation)
        return -torch.tensor([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)], dtype=F64)

    h = 1e-4                                                                # degrees
    image = shadowed_coverage(mesh, camera, colors, light(azimuth))
    d_image = ((shadowed_coverage(mesh, camera, colors, light(azimuth + h)) - image) / h).sum(-1)   # (H, W)
    line = (f"azimuth {azimuth:g}, elevation {elevation:g}: image mean {_r4(image.mean())}, "
            f"|d image / d azimuth| summed {_r4(d_image.abs().sum())} per degree")
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.9))
    show_image(image, ax=axes[0], srgb=False)
    axes[0].set_title(f"light: azimuth {azimuth:g}°, elevation {elevation:g}°", fontsize=10)
    signed_image(d_image, ax=axes[1])
    axes[1].set_title("d image / d azimuth (RGB summed)", fontsize=10)
    fig.colorbar(axes[1].images[0], ax=axes[1], fraction=0.046, pad=0.03,
                 label="per degree (red: brighter, blue: darker)")
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return dict(mean=float(image.mean()), gradient=float(d_image.abs().sum()), line=line)


def shadow_light_explorer() -> None:
    """Lecture 12: the light direction, the exact shadowed image and its gradient."""
    _show(draw_shadow_light)


# ------------------------------------------------------------------------------------------------ lecture 14

PENUMBRA_SIZE = 48                                                          # pixels a side of the floor's picture
PENUMBRA_OCCLUDER = ((-0.3, -0.25), (0.3, -0.3), (0.25, 0.3), (-0.35, 0.2))  # a flat quadrilateral at height 0.8


def draw_penumbra(size: float = 0.4, x: float = 0.3, height: float = 2.0) -> dict:
    """The floor under a square area light of half side ``size`` centred at (x, height, -0.2), facing down, and
    a flat quadrilateral occluder at height 0.8 (lecture 14's fits): the exact picture (``penumbra_picture``,
    ambient 0.05 + 12 F, linear values shown divided by the brightest pixel, so that a small light's dim
    picture is legible; the printed mean is the picture's own) and beside it its derivative with respect to the light's x, per pixel,
    by forward-mode autograd through ``light_form_factor`` (exact; red: brighter as the light moves to +x,
    blue: darker). The derivative lives in the penumbra and on the open floor (which the light's motion
    brightens on one side and darkens on the other); in the umbra it is 0. Grow the light and the penumbra
    widens, its gradient spreads and weakens; shrink it to a point and the penumbra collapses onto the hard
    shadow's edge, where the derivative concentrates (a Dirac in the limit: lecture 12's problem).
    """
    import torch.autograd.forward_ad as fwAD

    from ..shadows.area import light_form_factor
    from ..shadows.area_fit import AMBIENT, POWER, floor_points, polygon_mesh, square_light
    size = _check_range("size", size, 0.01, 2.0)
    x = _check_range("x", x, -3.0, 3.0)
    height = _check_range("height", height, 0.9, 5.0)
    occluder = polygon_mesh(torch.tensor(PENUMBRA_OCCLUDER, dtype=F64), 0.8)
    points, normals = floor_points(PENUMBRA_SIZE)
    centre = torch.tensor([x, height, -0.2], dtype=F64)
    with fwAD.dual_level():
        moving = fwAD.make_dual(centre, torch.tensor([1.0, 0.0, 0.0], dtype=F64))
        F = light_form_factor(points, normals, square_light(moving, size), occluder)
        value, tangent = fwAD.unpack_dual(F)
    n = PENUMBRA_SIZE
    image = (AMBIENT + POWER * value).view(n, n)
    d_image = (POWER * tangent).view(n, n)
    line = (f"half side {size:g}, x {x:g}, height {height:g}: picture mean {_r4(image.mean())}, "
            f"|d picture / dx| summed {_r4(d_image.abs().sum())}")
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.9))
    show_image((image / image.max()).unsqueeze(-1).expand(n, n, 3), ax=axes[0], srgb=False)
    axes[0].set_title(f"the floor (÷ its brightest): half side {size:g}, x = {x:g}, height {height:g}", fontsize=10)
    signed_image(d_image, ax=axes[1])
    axes[1].set_title("d picture / d (light x), exact", fontsize=10)
    fig.colorbar(axes[1].images[0], ax=axes[1], fraction=0.046, pad=0.03,
                 label="per unit (red: brighter, blue: darker)")
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return dict(mean=float(image.mean()), gradient=float(d_image.abs().sum()), line=line)


def penumbra_explorer() -> None:
    """Lecture 14: an area light's size and position, the penumbra and its exact gradient."""
    _show(draw_penumbra)


# ------------------------------------------------------------------------------------------------ lecture 15

GAUSSIAN_SIZE = 48                                                          # pixels a side


def draw_gaussian(scale: float = 0.5, angle: float = 30.0, opacity: float = 0.8, offset: float = -0.2) -> dict:
    """Two Gaussians (lecture 15's swap scene): the red one fixed, the blue one of standard deviations
    ``scale`` × (1, 0.4, 1) turned ``angle`` degrees about the view axis, opacity ``opacity``, moved ``offset``
    along the view direction from its swap point (negative: in front of the red one). Left: the splatted image
    (``render_gaussians``); right: its derivative with respect to the offset by forward-mode autograd. The
    derivative is what autograd sees: smooth on each side of 0, where the depth order flips and the image
    jumps (cross 0 and watch the colours trade places), while the derivative shows no trace of that jump.
    """
    import torch.autograd.forward_ad as fwAD

    from ..splats import render_gaussians, swap_scene
    scale = _check_range("scale", scale, 0.05, 2.0)
    angle = _check_range("angle", angle, -360.0, 360.0)
    opacity = _check_range("opacity", opacity, 0.0, 1.0)
    offset = _check_range("offset", offset, -2.0, 2.0)
    params, camera, toward, swap = swap_scene(GAUSSIAN_SIZE)
    means, scales, rotations, opacities, colors = (p.clone() for p in params)
    half = math.radians(angle) / 2
    axis = camera.R[2]                                                      # the view axis, world space
    rotations[1] = torch.cat([torch.tensor([math.cos(half)], dtype=F64), math.sin(half) * axis])
    scales[1] = scale * torch.tensor([1.0, 0.4, 1.0], dtype=F64)
    opacities[1] = opacity
    with fwAD.dual_level():
        s = fwAD.make_dual(torch.tensor(swap + offset, dtype=F64), torch.tensor(1.0, dtype=F64))
        moved = torch.stack([means[0], means[1] + s * toward])
        image, tangent = fwAD.unpack_dual(render_gaussians(moved, scales, rotations, opacities, colors, camera))
    d_image = tangent.sum(-1)
    order = "blue in front" if offset < 0 else "red in front"
    line = (f"scale {scale:g}, angle {angle:g}, opacity {opacity:g}, offset {offset:g} ({order}): image mean "
            f"{_r4(image.mean())}, |d image / d offset| summed {_r4(d_image.abs().sum())}")
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.9))
    show_image(image, ax=axes[0], srgb=False)
    axes[0].set_title(f"two Gaussians, {order}", fontsize=10)
    signed_image(d_image, ax=axes[1])
    axes[1].set_title("d image / d offset (RGB summed), autograd", fontsize=10)
    fig.colorbar(axes[1].images[0], ax=axes[1], fraction=0.046, pad=0.03, label="per unit of offset")
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return dict(mean=float(image.mean()), gradient=float(d_image.abs().sum()), line=line)


def gaussian_explorer() -> None:
    """Lecture 15: a Gaussian's scale, rotation and opacity, and the depth swap."""
    _show(draw_gaussian)


# ------------------------------------------------------------------------------------------------ the registry
# name -> (explorer, its draw function, its controls (see ``explorer``), True where it redraws as a slider moves,
# False where it redraws on release with its controls greyed out meanwhile)
EXPLORERS = {
    "03 fill rule": (fill_rule_explorer, draw_fill_rule,
                     dict(x=(0.0, 8.0, 0.25, 5.5), y=(0.0, 8.0, 0.25, 5.5), depth=(0.0, 1.0, 0.05, 0.5)), True),
    "05 supersampling": (supersampling_explorer, draw_supersampling,
                         dict(k=(1, 8, 1, 2), jitter=False, shape=["sliver", "teapot"]), False),
    "06 shadow map": (shadow_map_explorer, draw_shadow_map,
                      dict(resolution=(16, 512, 16, 64), bias=(0.0, 8.0, 0.25, 0.0), slope_bias=(0.0, 4.0, 0.25, 0.0),
                           pcf=[1, 3, 5, 7]), False),
    "07 BVH": (bvh_explorer, draw_bvh, dict(level=(0, BVH_DEPTH, 1, 3), heat=["boxes", "triangles"]), True),
    "07 area light": (area_light_explorer, draw_area_light, dict(size=(0.0, 2.0, 0.1, 1.0), samples=(1, 8, 1, 4)),
                      False),
    "08 soft rasterization": (soft_explorer, draw_soft,
                              dict(log_sigma=(-5.0, -1.0, 0.25, -2.5), log_gamma=(-4.0, 0.0, 0.25, -2.0)), True),
    "09 edge in a pixel": (edge_explorer, draw_edge,
                           dict(offset=(-1.0, 2.0, 0.05, 0.5), angle=(-60.0, 60.0, 5.0, 20.0)), True),
    "09 finite differences": (finite_difference_explorer, draw_finite_difference,
                              dict(log_step=(-12.0, -1.0, 0.5, -5.0)), False),
    "09 edge sampling": (edge_sampling_explorer, draw_edge_sampling, dict(log_samples=(1.0, 3.5, 0.5, 2.0)), False),
    "10 fit snapshots": (fit_explorer, draw_fit, dict(step=(0, FIT_STEPS, 1, FIT_STEPS)), True),
    "10 loss landscape": (loss_landscape_explorer, draw_loss_landscape,
                          dict(sigma=SIGMAS[1:2] + SIGMAS[:1] + SIGMAS[2:]), False),
    "11 style weight": (style_weight_explorer, draw_style_weight,
                        dict(weight=STYLE_WEIGHTS[3:4] + STYLE_WEIGHTS[:3] + STYLE_WEIGHTS[4:]), False),
    "12 shadow light": (shadow_light_explorer, draw_shadow_light,
                        dict(azimuth=(-180.0, 180.0, 5.0, 30.0), elevation=(15.0, 85.0, 5.0, 60.0)), False),
    "14 penumbra": (penumbra_explorer, draw_penumbra,
                    dict(size=(0.05, 0.8, 0.05, 0.4), x=(-1.0, 1.0, 0.1, 0.3), height=(1.2, 3.0, 0.1, 2.0)), False),
    "15 gaussian": (gaussian_explorer, draw_gaussian,
                    dict(scale=(0.1, 1.0, 0.05, 0.5), angle=(-90.0, 90.0, 5.0, 30.0), opacity=(0.05, 0.99, 0.02, 0.8),
                         offset=(-0.5, 0.5, 0.05, -0.2)), True),
}
