"""The ray-tracing benchmark: ``python -m course bench raytrace [--scenes S1 ...] [--scale F] [--vs embree]
[--plot FILE]``.

On the four standard scenes of ``bench raster`` (``course.bench.raster.scene``) and on ``thin``, a mix of long
thin slivers and large flat triangles (the hard case for a BVH: big, overlapping boxes), it reports

* the build time of ``BVH(mesh)``;
* Mrays/s of **primary** rays: ``raycast`` with the scene's camera at ``--scale`` of its resolution (full
  ``Fragments``; the rays are traced in float64, as ``raycast`` does);
* Mrays/s of **shadow** rays: ``visible`` (any hit) from every visible primary hit point to a point light;
* Mrays/s of **incoherent** rays: ``BVH.intersect`` (closest hit) of ``--incoherent`` rays with random origins
  in the scene's bounding sphere and random directions (seeded);
* the speed-up over **brute force**, the watertight test (``intersect_triangles``) of a ray against every
  triangle, chunked: timed on a small subset of the same rays (about ``--brute-pairs`` ray-triangle pairs) and
  extrapolated per ray; the subset's face ids are checked against the BVH's ("agree").

``--vs embree`` traces the same rays with Embree (``pip install embreex``) in the same run: scene construction
and commit (``EmbreeScene`` + ``TriangleMesh`` + the first query, which commits), ``run(..., query=
"INTERSECT")`` for primary and incoherent rays, ``query="OCCLUDED"`` for shadow rays, float32, and prints the
time ratio ours / Embree. Without embreex it is skipped with a message.

``--plot FILE`` (default ``raytrace_scaling.png``, ``''`` for none) writes ``plot_scaling``'s figure: time per
ray (µs) against face count, log-log, for brute force, the BVH and Embree (when run), primary and incoherent
rays: brute force grows like the face count, the BVH's traversal about like its logarithm.
"""
from __future__ import annotations

import math

import torch

from .. import kernels
from ..camera import Camera
from ..mesh import Mesh
from ..raytrace import BVH, _camera_rays, intersect_triangles, raycast, visible
from .kernels import cold_start_line
from .raster import SCENES as RASTER_SCENES
from .raster import scene as raster_scene
from .timing import time_it, time_side_by_side

__all__ = ["SCENES", "scene", "thin_scene", "brute_force", "measure", "bench_raytrace", "format_table",
           "plot_scaling", "add_arguments", "run"]

REPEAT = 3               # timed runs per measurement (these take seconds each)
DESCRIPTION = "ray tracing: BVH build, primary / shadow / incoherent Mrays/s, vs brute force (and Embree)"

SCENES = tuple(RASTER_SCENES) + ("thin",)
KINDS = ("build", "primary", "shadow", "incoherent")
LIGHT = (2.0, 3.0, 4.0)                                                     # the shadow rays' point light


def thin_scene(n_thin: int = 4000, n_flat: int = 16, size: int = 256, dtype=torch.float32):
    """(mesh, camera) of a box [-1, 1]³ holding ``n_thin`` long thin slivers (length 0.5, width 2e-3,
    random orientation) and ``n_flat`` large flat triangles (about 1.6 across, tilted a little), seeded."""
    g = torch.Generator().manual_seed(0)
    c = torch.rand(n_thin, 3, generator=g, dtype=torch.float64) * 1.6 - 0.8
    a = torch.nn.functional.normalize(torch.randn(n_thin, 3, generator=g, dtype=torch.float64), dim=1)
    w = torch.nn.functional.normalize(torch.linalg.cross(a, torch.randn(n_thin, 3, generator=g,
                                                                        dtype=torch.float64)), dim=1)
    thin = torch.stack([c - 0.25 * a, c + 0.25 * a, c + 2e-3 * w], 1)       # (n_thin, 3, 3)
    h = torch.rand(n_flat, generator=g, dtype=torch.float64) * 1.8 - 0.9
    ang = torch.rand(n_flat, generator=g, dtype=torch.float64) * 2 * math.pi
    corners = torch.stack([torch.cos(ang), torch.sin(ang)], 1)             # rotating triangles in xz
    pts = []
    for k in range(3):
        phi = ang + 2 * math.pi * k / 3
        x, z = 0.9 * torch.cos(phi), 0.9 * torch.sin(phi)
        tilt = 0.1 * (corners[:, 0] * x + corners[:, 1] * z)
        pts.append(torch.stack([x, h + tilt, z], 1))
    flat = torch.stack(pts, 1)                                              # (n_flat, 3, 3)
    tris = torch.cat([thin, flat]).to(dtype)
    mesh = Mesh(tris.reshape(-1, 3), torch.arange(tris.shape[0] * 3).reshape(-1, 3))
    cam = Camera.look_at((1.6, 1.2, 3.2), (0.0, 0.0, 0.0), fov_y=40.0, width=size, height=size, dtype=dtype)
    return mesh, cam


def scene(name: str, dtype=torch.float32):
    """(mesh, camera) of a benchmark scene: S1-S4 of ``bench raster``, or ``thin``."""
    if name == "thin":
        return thin_scene(dtype=dtype)
    if name in RASTER_SCENES:
        return raster_scene(name, dtype=dtype)
    raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")


def _scaled(camera, scale: float):
    """The camera with its image scaled by ``scale`` (same field of view)."""
    w, h = max(1, round(camera.width * scale)), max(1, round(camera.height * scale))
    K = camera.K.clone()
    K[0, :] *= w / camera.width
    K[1, :] *= h / camera.height
    return Camera(K, camera.R, camera.t, w, h, near=camera.near, far=camera.far, orthographic=camera.orthographic)


def brute_force(origins, directions, tris, *, t_min=0.0, t_max=math.inf, any_hit=False, pairs: int = 1 << 20):
    """Closest (or any) hit of each ray against every triangle by the watertight test, no BVH: (N,) face id,
    -1 on a miss, ties in t to the lower face id. Pairs are tested in chunks of about ``pairs``."""
    N, F = origins.shape[0], tris.shape[0]
    t_lo = torch.as_tensor(t_min, dtype=origins.dtype).expand(N)
    t_hi = torch.as_tensor(t_max, dtype=origins.dtype).expand(N)
    best = torch.full((N,), math.inf, dtype=origins.dtype)
    face = torch.full((N,), -1, dtype=torch.int64)
    per = max(1, pairs // max(N, 1))                                       # triangles per chunk
    for s in range(0, F, per):
        tri = tris[s:s + per]
        n = tri.shape[0]
        o, d = origins.repeat_interleave(n, 0), directions.repeat_interleave(n, 0)
        t, _, hit = intersect_triangles(o, d, tri.repeat(N, 1, 1))
        t = torch.where(hit & (t >= t_lo.repeat_interleave(n)) & (t <= t_hi.repeat_interleave(n)), t,
                        torch.full_like(t, math.inf)).view(N, n)
        tmin, arg = t.min(1)                                                # first index on ties: lower id
        better = tmin < best
        best, face = torch.where(better, tmin, best), torch.where(better, arg + s, face)
        if any_hit and bool((face >= 0).all()):
            break
    return face


# ---------------------------------------------------------------------------------------- Embree (optional)

class _Embree:
    """The same rays through Embree (embreex), float32."""

    def __init__(self):
        import embreex.mesh_construction                                    # optional dependency  # noqa: F401
        import embreex.rtcore_scene                                         # noqa: F401
        import numpy as np
        self.np = np

    def build(self, mesh):
        from embreex.mesh_construction import TriangleMesh
        from embreex.rtcore_scene import EmbreeScene
        np = self.np
        verts = mesh.verts.detach().float().numpy().astype(np.float32)
        faces = mesh.faces.numpy().astype(np.int32)
        sc = EmbreeScene()
        TriangleMesh(sc, verts, faces)
        sc.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # the first query commits
        return sc

    def trace(self, sc, o, d, *, dists=None, occluded=False):
        np = self.np
        o = np.ascontiguousarray(o.float().numpy())
        d = np.ascontiguousarray(d.float().numpy())
        kw = {} if dists is None else dict(dists=np.ascontiguousarray(dists.float().numpy()))
        return sc.run(o, d, query="OCCLUDED" if occluded else "INTERSECT", **kw)


def _embree():
    try:
        return _Embree(), None
    except Exception as err:                                                # not installed, or no binary wheel
        return None, (f"--vs embree skipped: embreex is not available here ({type(err).__name__}: {err}).\n"
                      "  Install it with `pip install embreex` (or `pip install -e \".[bench]\"`).")


# ------------------------------------------------------------------------------------------- measurement

def _rays(mesh, camera, bvh, n_incoherent: int, seed: int = 0):
    """Primary rays (float64, with t ranges), shadow-ray inputs and incoherent rays of one scene."""
    o, d, dz = _camera_rays(camera)
    t_lo, t_hi = camera.near / dz, camera.far / dz
    frags = raycast(mesh, camera, bvh=bvh)
    hit = frags.face_id.reshape(-1) >= 0
    pts = (o + d * (frags.depth.reshape(-1, 1).double() / dz[:, None]))[hit]
    g = torch.Generator().manual_seed(seed)
    lo, hi = bvh.bounds[0].double(), bvh.bounds[1].double()
    centre, radius = (lo + hi) / 2, float((hi - lo).norm()) / 2
    u = torch.nn.functional.normalize(torch.randn(n_incoherent, 3, generator=g, dtype=torch.float64), dim=1)
    r = radius * torch.rand(n_incoherent, 1, generator=g, dtype=torch.float64) ** (1 / 3)
    inc_o = centre + u * r
    inc_d = torch.nn.functional.normalize(torch.randn(n_incoherent, 3, generator=g, dtype=torch.float64), dim=1)
    return dict(primary=(o, d, t_lo, t_hi), points=pts, incoherent=(inc_o, inc_d), radius=radius)


def _subset(n: int, k: int) -> torch.Tensor:
    """k indices spread evenly over range(n)."""
    k = max(1, min(n, k))
    return torch.linspace(0, n - 1, k).round().long()


def measure(name: str, repeat: int = 3, scale: float = 0.25, n_incoherent: int = 1 << 15,
            brute_pairs: int = 1 << 21, embree=None, scene_override=None) -> list[dict]:
    """Rows (one per kind: build, primary, shadow, incoherent) for one scene: rays, ms, mrays_s, brute-force
    ms per ray (on ``brute_rays`` rays), speed-up over it, agreement with it; embree_ms and ratio with
    ``embree`` (an ``_Embree``). scene_override: (mesh, camera) to measure instead (``name`` labels rows)."""
    mesh, cam = scene(name) if scene_override is None else scene_override
    cam = _scaled(cam, scale)
    F = mesh.num_faces
    bvh = BVH(mesh)
    rays = _rays(mesh, cam, bvh, n_incoherent)
    o, d, t_lo, t_hi = rays["primary"]
    pts = rays["points"]
    light = torch.tensor(LIGHT, dtype=torch.float64)
    offset = 1e-4 * 2 * rays["radius"]                                      # visible()'s default offset
    inc_o, inc_d = rays["incoherent"]
    tris64 = mesh.verts.detach().double()[mesh.faces]
    n_brute = max(2, brute_pairs // F)
    rows = []

    def row(kind, n, ms, **extra):
        r = dict(scene=name, faces=F, kind=kind, rays=n, ms=ms, mrays_s=n / ms / 1e3 if n else None, **extra)
        rows.append(r)
        return r

    es = embree.build(mesh) if embree is not None else None
    twin = kernels.backend() == "numba" and kernels.available()             # also time the torch path

    def timed(fn, *others):
        """Median ms of fn, the others (Embree) and, with the kernels in force, fn on the torch path, side by
        side; returns (ms, [others' ms], torch ms or None)."""
        fns = [fn, *others]
        if twin:
            def on_torch():
                with kernels.using("torch"):
                    return fn()
            fns.append(on_torch)
        ts = time_side_by_side(fns, repeat)
        return ts[0], ts[1:1 + len(others)], ts[-1] if twin else None

    # build
    fns = [lambda: BVH(mesh)] + ([lambda: embree.build(mesh)] if embree else [])
    ts = time_side_by_side(fns, repeat)
    row("build", 0, ts[0], embree_ms=ts[1] if embree else None)
    # primary
    pix = _subset(o.shape[0], n_brute)
    face_bvh = bvh.intersect(o[pix], d[pix], t_min=t_lo[pix], t_max=t_hi[pix]).face_id
    face_bf = brute_force(o[pix], d[pix], tris64, t_min=t_lo[pix], t_max=t_hi[pix])
    brute_ms = time_it(lambda: brute_force(o[pix], d[pix], tris64, t_min=t_lo[pix], t_max=t_hi[pix]), 1,
                       warmup=0) / pix.numel()
    ms, other, torch_ms = timed(lambda: raycast(mesh, cam, bvh=bvh),
                                *([lambda: embree.trace(es, o, d)] if embree else []))
    row("primary", o.shape[0], ms, brute_rays=pix.numel(), brute_ms_per_ray=brute_ms,
        agree=float((face_bvh == face_bf).double().mean()), embree_ms=other[0] if embree else None,
        torch_ms=torch_ms)
    # shadow rays: any hit, from the visible hit points to the light
    if pts.shape[0]:
        sd = light - pts
        dist = sd.norm(dim=1)
        sub = _subset(pts.shape[0], n_brute)
        s_lo, s_hi = offset / dist, 1 - offset / dist
        blocked_bf = brute_force(pts[sub], sd[sub], tris64, t_min=s_lo[sub], t_max=s_hi[sub], any_hit=True) >= 0
        free = visible(pts[sub], light, bvh)
        brute_ms = time_it(lambda: brute_force(pts[sub], sd[sub], tris64, t_min=s_lo[sub], t_max=s_hi[sub],
                                               any_hit=True), 1, warmup=0) / sub.numel()
        e_o, e_d = pts + sd * s_lo[:, None], sd
        e_dist = s_hi - s_lo
        ms, other, torch_ms = timed(lambda: visible(pts, light, bvh), *(
            [lambda: embree.trace(es, e_o, e_d, dists=e_dist, occluded=True)] if embree else []))
        row("shadow", pts.shape[0], ms, brute_rays=sub.numel(), brute_ms_per_ray=brute_ms,
            agree=float((free == ~blocked_bf).double().mean()), embree_ms=other[0] if embree else None,
            torch_ms=torch_ms)
    # incoherent rays: closest hit
    sub = _subset(inc_o.shape[0], n_brute)
    face_bvh = bvh.intersect(inc_o[sub], inc_d[sub]).face_id
    face_bf = brute_force(inc_o[sub], inc_d[sub], tris64)
    brute_ms = time_it(lambda: brute_force(inc_o[sub], inc_d[sub], tris64), 1, warmup=0) / sub.numel()
    ms, other, torch_ms = timed(lambda: bvh.intersect(inc_o, inc_d),
                                *([lambda: embree.trace(es, inc_o, inc_d)] if embree else []))
    row("incoherent", inc_o.shape[0], ms, brute_rays=sub.numel(), brute_ms_per_ray=brute_ms,
        agree=float((face_bvh == face_bf).double().mean()), embree_ms=other[0] if embree else None,
        torch_ms=torch_ms)
    for r in rows:
        if r.get("brute_ms_per_ray") is not None:
            r["speedup"] = r["brute_ms_per_ray"] * r["rays"] / r["ms"]
        if r.get("embree_ms"):
            r["ratio"] = r["ms"] / r["embree_ms"]
    return rows


def format_table(rows) -> str:
    emb = any(r.get("embree_ms") for r in rows)
    twin = any(r.get("torch_ms") for r in rows)
    head = (f"{'scene':<7}{'faces':>9} {'rays':<11}{'count':>8}{'ms':>10}{'Mrays/s':>9}"
            + (f"{'torch ms':>10}" if twin else "") + f"{'brute ms/ray':>14}{'speed-up':>10}{'agree':>8}")
    head += f"{'Embree ms':>11}{'Mrays/s':>9}{'ours/Embree':>13}" if emb else ""
    lines = [head, "-" * len(head)]
    for r in rows:
        def f(key, fmt, width):
            v = r.get(key)
            return f"{v:>{width}{fmt}}" if v is not None else " " * (width - 1) + "-"
        line = (f"{r['scene']:<7}{r['faces']:>9,} {r['kind']:<11}{r['rays'] or '':>8}{r['ms']:>10.1f}"
                + f("mrays_s", ".3g", 9) + (f("torch_ms", ".1f", 10) if twin else "")
                + f("brute_ms_per_ray", ".3f", 14) + f("speedup", ".0f", 10)
                + (f"{100 * r['agree']:>7.1f}%" if r.get("agree") is not None else f"{'-':>8}"))
        if emb:
            e = r.get("embree_ms")
            line += f(("embree_ms"), ".2f", 11)
            line += f"{r['rays'] / e / 1e3:>9.3g}" if e and r["rays"] else f"{'-':>9}"
            line += f("ratio", ".1f", 13)
        lines.append(line)
    return "\n".join(lines)


SCALING_KINDS = ("primary", "incoherent")              # the ray kinds plot_scaling draws


def _us_per_ray(rows, kind: str, key: str) -> list[tuple[int, float, str]]:
    """(faces, µs per ray, scene) of the ``kind`` rows that have ``key``, sorted by face count. key: "ms" (the
    BVH), "embree_ms" or "brute_ms_per_ray" (already per ray)."""
    pts = []
    for r in rows:
        if r.get("kind") != kind or not r.get(key) or not r.get("rays"):
            continue
        ms = r[key] if key == "brute_ms_per_ray" else r[key] / r["rays"]
        pts.append((int(r["faces"]), 1e3 * ms, str(r["scene"])))
    return sorted(pts)


def plot_scaling(rows, path=None):
    """Log-log figure of time per ray (µs) against face count, one line per method and ray kind.

    rows: ``measure`` / ``bench_raytrace`` rows (dicts with ``scene``, ``faces``, ``kind``, ``rays``, ``ms``, and
    where measured ``brute_ms_per_ray`` and ``embree_ms``). Draws, for the kinds in ``SCALING_KINDS`` (primary,
    incoherent): "brute force, KIND" (dashed, ``brute_ms_per_ray``), "BVH, KIND" (solid, ``ms / rays``: the
    compiled kernels where they ran) and, when the rows have them, "Embree, KIND" (dotted) and "BVH, torch
    path, KIND" (dash-dot, ``torch_ms``), each point labelled with its scene; and a grey
    guide "∝ faces" through the first brute-force point, the slope brute force should follow. path: where to
    save it (None: don't). Returns the matplotlib figure. Raises ValueError when no row has rays to plot.
    """
    import matplotlib.pyplot as plt
    rows = list(rows)
    methods = (("brute force", "brute_ms_per_ray", "--", "s"), ("BVH", "ms", "-", "o"),
               ("Embree", "embree_ms", ":", "^"), ("BVH, torch path", "torch_ms", "-.", "x"))
    lines = []                                                              # (label, points, style, marker, colour)
    for m, (method, key, style, marker) in enumerate(methods):
        for k, kind in enumerate(SCALING_KINDS):
            pts = _us_per_ray(rows, kind, key)
            if pts:
                colour = 2 * m + k
                lines.append((f"{method}, {kind}", pts, style, marker, f"C{colour + (colour >= 7)}"))   # C7: grey
    if not lines:
        raise ValueError("plot_scaling: no primary or incoherent rows with rays and times to plot "
                         "(expected the rows of measure() / bench_raytrace())")
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, pts, style, marker, color in lines:
        faces, us = [p[0] for p in pts], [p[1] for p in pts]
        ax.plot(faces, us, ls=style, marker=marker, color=color, label=label)
        for f, u, name in pts:
            ax.annotate(name, (f, u), fontsize=7, xytext=(3, 3), textcoords="offset points", color=color)
    brute = next((pts for label, pts, *_ in lines if label.startswith("brute force")), None)
    all_faces = sorted({p[0] for _, pts, *_ in lines for p in pts})
    if brute and all_faces[-1] > all_faces[0]:
        f0, u0 = brute[0][:2]
        ax.plot(all_faces, [u0 * f / f0 for f in all_faces], color="0.6", lw=1, ls="-.", label="∝ faces")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("faces")
    ax.set_ylabel("time per ray (µs)")
    ax.set_title("ray tracing: time per ray against scene size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig


def bench_raytrace(names=SCENES, repeat: int = 3, scale: float = 0.25, n_incoherent: int = 1 << 15,
                   brute_pairs: int = 1 << 21, vs_embree: bool = False, plot: str | None = None,
                   out=print) -> list[dict]:
    """The whole benchmark: one table, rows per scene and kind; with ``plot`` a path, ``plot_scaling``'s
    figure saved there (the command line's ``--plot`` defaults to ``raytrace_scaling.png``)."""
    embree = None
    if vs_embree:
        embree, msg = _embree()
        if msg:
            out(msg)
    rows = [r for name in names
            for r in measure(name, repeat, scale, n_incoherent, brute_pairs, embree)]
    out(f"primary rays: raycast at {scale:g} of each scene's resolution (float64 rays, full Fragments); shadow: "
        f"visible() to a point light at {LIGHT}; incoherent: {n_incoherent} random rays, closest hit.\n"
        f"brute force: the watertight test against every triangle on 'brute rays' of them (about "
        f"{brute_pairs:,} ray-triangle pairs), extrapolated per ray; 'agree': same face (or same visibility) "
        f"as the BVH on those rays.")
    out(format_table(rows))
    if any(r.get("torch_ms") for r in rows):
        out("ms: with the compiled kernels (course.kernels); torch ms: the torch path (COURSE_KERNELS=torch), "
            "side by side in the same run.")
        cold_start_line(out)
    if embree is not None:
        out("Embree: float32, EmbreeScene + TriangleMesh + first query (commit) for build; run(query='INTERSECT' "
            "/ 'OCCLUDED'). Targets: primary rays (full Fragments) within 3x on S1 and 4x on S2, shadow and "
            "incoherent rays within 4x, build within 3x on S2.")
        for r in rows:
            if r["scene"] in ("S1", "S2") and r.get("ratio"):
                out(f"  {r['scene']} {r['kind']}: ours / Embree = {r['ratio']:.1f}")
    if plot:
        plot_scaling(rows, plot)
        out(f"\nscaling plot written to {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES, metavar="SCENE",
                        help=f"scenes to run (default all: {', '.join(SCENES)})")
    parser.add_argument("--scale", type=float, default=0.25,
                        help="primary rays: the scene's image scaled by this (default 0.25: S1 at 128²)")
    parser.add_argument("--incoherent", type=int, default=1 << 15, help="number of incoherent rays")
    parser.add_argument("--brute-pairs", type=int, default=1 << 21,
                        help="ray-triangle pairs of the brute-force subset (rays = this / faces)")
    parser.add_argument("--vs", choices=["embree"], help="also trace with Embree (embreex) and report the ratio")
    parser.add_argument("--plot", default="raytrace_scaling.png",
                        help="where to save the time-per-ray against faces plot ('' for none)")


def run(args) -> list[dict]:
    return bench_raytrace(args.scenes, args.repeat, args.scale, args.incoherent, args.brute_pairs,
                          vs_embree=args.vs == "embree", plot=args.plot or None)
