"""The visibility-gradient benchmark: ``python -m course bench gradients [--scenes ...] [--full] [--plot FILE]
[--vs mitsuba]``.

Every method of ``course.visibility.image_gradient`` against its ``"exact"`` gradient (autograd through the
closed-form box-filtered image), as run time against error, on fixed scenes, in float64 unless a row says
float32. The loss is ``L = Σ weights ⊙ image`` with two kinds of weights:

* **L2**: ``weights = 2 (image - target)``, the gradient of ``‖image - target‖²``, with the target the same
  scene after a small rigid move of the mesh (2° about y, a shift of (0.03, -0.02, 0)), both images from
  ``course.coverage.exact_coverage``: what an optimiser sees;
* **random**: seeded standard normal weights, every pixel counts.

Methods: ``exact`` (the reference, timed too), ``reynolds`` (orders 1 and 2), ``edge_sampling`` (several sample
counts, seed 0), ``reparameterization`` (the bounded warp, 16 and 256 samples per pixel that holds a jump,
seed 0; the harmonic warp at 256 beside it), ``finite_differences`` (central, several steps, float64 and float32), ``soft`` (several σ,
NDC units, γ = 1e-4) and ``nmr``. Soft and NMR differentiate a different image (a blurred one, the hard one),
so their error measures how far their gradient is from the box-filtered image's, not an estimator's error.

Scenes (names for ``--scenes``):

=============  ====================================================================================  ========
name           what                                                                                  default
=============  ====================================================================================  ========
triangle       one triangle, 32²                                                                      yes
triangles      two overlapping triangles, one in front (occlusion), 32²                               yes
S4-64          S4's icosphere (1,280 faces), off-axis camera, 64²                                     yes
S4-256         the same at 256²                                                                       yes
spheres        two icospheres(2), the small one in front of the big one (occlusion, no intersection)  yes
pose           S4's icosphere at 64², the gradient w.r.t. the camera's R, t and focal length           yes
affine         S4-64 with vertex colours (``model="affine"``)                                          yes
S1             S1's icosphere(5) (20,480 faces) at 512²: tens of seconds per method                   --full
=============  ====================================================================================  ========

The camera is off-axis (``Camera.look_at((0.13, 0.21, 3.0), (0.01, -0.02, 0.0), fov_y=40)``): seen on-axis
the icosphere puts symmetric edges exactly on pixel borders, where the derivative is one-sided and no two
methods need agree. Finite differences over every vertex of a big mesh are thousands of closed-form images,
so on meshes with more than ``FD_ALL_VERTICES`` vertices they run on a fixed seeded subset of the vertices the
loss depends on (exact gradient not zero), and their error is over those entries only; the output says so.

Error: the relative L2 error ``‖g - g*‖ / ‖g*‖`` over all entries (where ``g* = 0``: the absolute error
``‖g‖``, flagged "abs"), and the cosine similarity of g and g*. With several parameters (the pose row) the
error is the largest of the parameters' relative errors, and the cosine is taken with each parameter's block
scaled by 1 / ‖g*‖ of that block, so that R, t and f count alike. Times: the method's own forward and
gradient (one ``image_gradient`` call), the median of ``--repeat`` runs (a call over a second is run once).

``--vs mitsuba`` (the ``bench`` extra: ``pip install mitsuba``) adds Mitsuba 3's ``direct_projective``
integrator (projective sampling; Zhang, Roussel and Jakob, SIGGRAPH Asia 2023) on the same scenes: every face
an area emitter of its colour (a ``mesh_attribute`` face colour), a black BSDF, a box reconstruction filter,
a perspective sensor matching our camera, float32 (``llvm_ad_rgb``), at ``--mitsuba-spp`` samples per pixel;
``dr.backward`` of ``Σ weights ⊙ image`` gives the vertex gradient. Before any gradient is compared, Mitsuba's
image of the triangle scene is checked against ``exact_coverage`` (it must agree to Monte Carlo noise).
Projective sampling differentiates geometric silhouettes and occlusion boundaries, not the jump of emission
across an edge two faces share, so on meshes with random face colours it misses most of the gradient; the
rows "Mitsuba 1 col/object" repeat the comparison with one colour per connected mesh, where it must agree.
Dr.Jit's LLVM backend needs an LLVM it can compile with: set ``DRJIT_LIBLLVM_PATH``; otherwise the bench
tries the system's libLLVM and newer ones it finds, each in a subprocess first (LLVM 15 aborts the process
with "Cannot select: fmaximum"), and skips Mitsuba with the reason when none works.
"""
from __future__ import annotations

import glob
import math
import os
import statistics
import subprocess
import sys
import time

import torch

from ..camera import Camera
from ..coverage import exact_coverage
from ..coverage_affine import exact_affine_coverage
from ..mesh import Mesh, join_meshes
from ..models import icosphere
from ..visibility import image_gradient

__all__ = ["SCENES", "DEFAULT_SCENES", "make_scene", "weights_for", "method_specs", "gradient_error",
           "measure_scene", "bench_gradients", "format_table", "plot_pareto", "mitsuba_rows", "add_arguments",
           "run"]

REPEAT = 3               # timed runs per measurement (a call over a second is run once)
DESCRIPTION = ("visibility gradients (finite differences, edge sampling, Reynolds, reparameterization, soft, NMR) "
               "against the exact gradient: time against error, a table and a Pareto plot")

SCENES = ("triangle", "triangles", "S4-64", "S4-256", "spheres", "pose", "affine", "S1")
DEFAULT_SCENES = ("triangle", "triangles", "S4-64", "S4-256", "spheres", "pose", "affine")
WEIGHTS = ("L2", "random")
FD_STEPS = {torch.float64: (1e-3, 1e-5, 1e-7), torch.float32: (1e-2, 1e-3, 1e-4)}
SAMPLES = (1_000, 10_000, 100_000)
WARP_SAMPLES = (16, 256)                 # reparameterization: samples per pixel that holds a jump
SIGMAS = (1e-5, 1e-4, 1e-3)
ORDERS = (1, 2)
FD_ALL_VERTICES = 12     # meshes with more vertices: finite differences on a seeded subset
FD_VERTICES = 6          # that subset's size
MITSUBA_SPP = (1, 4, 16, 64)
EYE, TARGET = (0.13, 0.21, 3.0), (0.01, -0.02, 0.0)                         # the off-axis camera
EPS = 1e-300
ONCE_MS = 1000.0         # calls slower than this are timed once


# ------------------------------------------------------------------------------------------------ scenes

def _camera(size, fov=40.0):
    return Camera.look_at(EYE, TARGET, fov_y=fov, width=size, height=size, dtype=torch.float64)


def _colors(n, seed=1):
    return 0.2 + 0.8 * torch.rand(n, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def make_scene(name: str) -> dict:
    """The scene ``name`` (one of ``SCENES``): a dict with ``mesh``, ``camera``, ``colors`` ((F, 3) flat, or
    (V, 3) for ``model="affine"``), ``model``, ``background``, ``wrt`` (names for ``image_gradient``) and
    ``label`` (one line saying what it is). Everything float64; every face front-facing where it is seen."""
    f64 = torch.float64
    if name in ("triangle", "triangles"):
        a = torch.tensor([[-0.6, -0.5, 0.1], [0.7, -0.3, 0.0], [0.0, 0.6, -0.1]], dtype=f64)
        if name == "triangle":
            mesh, label = Mesh(a, torch.tensor([[0, 1, 2]])), "one triangle"
        else:
            b = torch.tensor([[-0.25, -0.15, 0.6], [0.85, 0.05, 0.55], [0.35, 0.9, 0.5]], dtype=f64)
            mesh = Mesh(torch.cat([a, b]), torch.tensor([[0, 1, 2], [3, 4, 5]]))
            label = "two triangles, the second in front of the first (occlusion)"
        cam = _camera(32)
    elif name in ("S4-64", "S4-256", "pose", "affine", "S1"):
        sub, size = {"S1": (5, 512), "S4-256": (3, 256)}.get(name, (3, 64))
        mesh = icosphere(sub, dtype=f64)
        cam = _camera(size)
        label = f"icosphere({sub}), off-axis camera"
    elif name == "spheres":
        big, small = icosphere(2, dtype=f64), icosphere(2, dtype=f64)
        mesh = join_meshes([big, Mesh(small.verts * 0.45 + torch.tensor([0.4, 0.3, 1.5], dtype=f64), small.faces)])
        cam = _camera(128, fov=60.0)
        label = "two icospheres(2), the small one in front (occlusion, no intersection)"
    else:
        raise ValueError(f"unknown scene {name!r}; scenes: {', '.join(SCENES)}")
    model = "affine" if name == "affine" else "flat"
    n = mesh.verts.shape[0] if model == "affine" else mesh.faces.shape[0]
    wrt = ("R", "t", "focal") if name == "pose" else ("verts",)
    label = (f"{label}; {mesh.faces.shape[0]:,} faces, {mesh.verts.shape[0]:,} vertices, {cam.width}²"
             + ("; gradient w.r.t. the camera's R, t, focal (FD: h=1e-5 in float64, 1e-3 in float32)"
                if name == "pose" else "")
             + ("; vertex colours (model='affine')" if model == "affine" else ""))
    # the pose row differences whole images (13 parameters): one step per dtype keeps the default run short
    fd_steps = {1e-5, 1e-3} if name == "pose" else None
    return dict(name=name, mesh=mesh, camera=cam, colors=_colors(n), model=model,
                background=(0.0, 0.0, 0.0), wrt=wrt, label=label, fd_steps=fd_steps)


# the closed-form image of each image model
IMAGE_MODELS = {"flat": exact_coverage, "affine": exact_affine_coverage}


def _model_missing(model) -> str | None:
    """None when ``image_gradient`` and the bench can do ``model``; else why not."""
    mesh = Mesh(torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64), torch.tensor([[0, 1, 2]]))
    cam = Camera.look_at((0.3, 0.3, 3.0), (0.3, 0.3, 0.0), fov_y=40, width=4, height=4, dtype=torch.float64)
    colors = torch.ones(3 if model == "affine" else 1, 3, dtype=torch.float64)
    try:
        image_gradient(mesh, cam, colors, torch.ones(4, 4, 3, dtype=torch.float64), method="exact", model=model)
    except ValueError as err:
        return f"image_gradient does not support it yet ({err})"
    if model not in IMAGE_MODELS:
        return (f"no closed-form image for model={model!r} in course.bench.gradients.IMAGE_MODELS (the L2 weights' "
                f"target needs one)")
    return None


def _moved(mesh, degrees=2.0, shift=(0.03, -0.02, 0.0)):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    rot = torch.tensor([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=mesh.verts.dtype)
    return Mesh(mesh.verts @ rot.T + torch.tensor(shift, dtype=mesh.verts.dtype), mesh.faces)


def weights_for(scene: dict, kind: str, seed: int = 0) -> torch.Tensor:
    """(H, W, 3) weights: ``"L2"``, 2 (image - target) with the target the mesh after a small rigid move,
    both closed-form images; ``"random"``, seeded standard normal."""
    cam = scene["camera"]
    if kind == "random":
        return torch.randn(cam.height, cam.width, 3, generator=torch.Generator().manual_seed(seed),
                           dtype=torch.float64)
    if kind != "L2":
        raise ValueError(f"weights must be one of {WEIGHTS}, got {kind!r}")
    image = IMAGE_MODELS[scene["model"]]
    with torch.no_grad():
        now = image(scene["mesh"], cam, scene["colors"], scene["background"])
        target = image(_moved(scene["mesh"]), cam, scene["colors"], scene["background"])
    return 2 * (now - target)


# ----------------------------------------------------------------------------------------------- methods

def method_specs(steps=None, samples=SAMPLES, sigmas=SIGMAS, orders=ORDERS, warp_samples=WARP_SAMPLES) -> list[dict]:
    """The methods of one scene, each ``dict(method, family, param, dtype, options)``, exact first."""
    steps = FD_STEPS if steps is None else steps
    specs = [dict(method="exact", family="exact", param="", dtype="float64", options={})]
    specs += [dict(method="reynolds", family="reynolds", param=f"order {k}", dtype="float64", options=dict(order=k))
              for k in orders]
    specs += [dict(method="edge_sampling", family="edge sampling", param=f"{n:,} smp", dtype="float64",
                   options=dict(samples=n, seed=0)) for n in samples]
    specs += [dict(method="reparameterization", family="reparameterization", param=f"{n:,} spp", dtype="float64",
                   options=dict(samples=n, seed=0)) for n in warp_samples]
    specs += [dict(method="reparameterization", family="reparam. (harmonic)", param=f"{n:,} spp", dtype="float64",
                   options=dict(samples=n, seed=0, warp="harmonic")) for n in warp_samples[-1:]]
    for dtype, hs in steps.items():
        name = str(dtype).replace("torch.", "")
        specs += [dict(method="finite_differences", family=f"FD {name}", param=f"h={h:.0e}", dtype=name,
                       options=dict(step=h, scheme="central", dtype=dtype)) for h in hs]
    specs += [dict(method="soft", family="soft (other image)", param=f"σ={s:.0e}", dtype="float64",
                   options=dict(sigma=s)) for s in sigmas]
    specs.append(dict(method="nmr", family="NMR (other image)", param="", dtype="float64", options={}))
    return specs


def gradient_error(g, ref, mask=None) -> dict:
    """Error of gradients ``g`` against ``ref`` (tuples of tensors, one per parameter; ``mask`` a tuple of
    boolean masks of the entries to compare, or None for all). ``rel``: the largest relative L2 error over the
    parameters (the absolute error for a parameter whose reference is zero; ``abs`` True then); ``cos``: the
    cosine similarity of the concatenated gradients, each parameter's block scaled by 1 / ‖reference block‖."""
    rels, a, b, absolute = [], [], [], False
    for k, (x, y) in enumerate(zip(g, ref)):
        x, y = x.detach().double().reshape(-1), y.detach().double().reshape(-1)
        if mask is not None and mask[k] is not None:
            m = mask[k].reshape(-1)
            x, y = x[m], y[m]
        ny = float(y.norm())
        diff = float((x - y).norm())
        if ny == 0:
            absolute = True
            rels.append(diff)
            continue
        rels.append(diff / max(ny, EPS))
        a.append(x / ny)
        b.append(y / ny)
    if a:
        a, b = torch.cat(a), torch.cat(b)
        cos = float((a @ b) / max(float(a.norm() * b.norm()), EPS))
    else:
        cos = math.nan
    return dict(rel=max(rels) if rels else math.nan, cos=cos, abs=absolute)


def _timed(fn, repeat):
    """(result of the first call, median ms); calls slower than ONCE_MS are run once."""
    start = time.perf_counter()
    out = fn()
    times = [1000 * (time.perf_counter() - start)]
    if times[0] < ONCE_MS:
        for _ in range(max(repeat, 1) - 1):
            start = time.perf_counter()
            fn()
            times.append(1000 * (time.perf_counter() - start))
    return out, statistics.median(times)


def _fd_vertices(exact_verts, n, seed=0):
    """A seeded subset of ``n`` vertices among those whose exact gradient is not zero (all of them if few); a
    hidden vertex can carry a rounding-level value (1e-36, from zero-area pieces), which counts as zero."""
    size = exact_verts.abs().sum(1)
    live = (size > 1e-12 * size.max()).nonzero().squeeze(1)
    if live.numel() <= n:
        return live.tolist()
    pick = torch.randperm(live.numel(), generator=torch.Generator().manual_seed(seed))[:n]
    return sorted(live[pick].tolist())


def measure_scene(scene: dict, weights_kind: str, specs=None, repeat: int = REPEAT, fd_vertices: int = FD_VERTICES,
                  out=print) -> list[dict]:
    """One row per method (``method_specs``) on one scene and one kind of weights."""
    specs = method_specs() if specs is None else specs
    w = weights_for(scene, weights_kind)
    args = (scene["mesh"], scene["camera"], scene["colors"], w)
    common = dict(model=scene["model"], background=scene["background"], wrt=scene["wrt"])
    ref, exact_ms = _timed(lambda: image_gradient(*args, method="exact", **common), repeat)
    subset = None
    if "verts" in scene["wrt"] and scene["mesh"].verts.shape[0] > FD_ALL_VERTICES:
        subset = _fd_vertices(ref[scene["wrt"].index("verts")], fd_vertices)
    rows = []
    for spec in specs:
        opts = dict(spec["options"])
        if spec["method"] == "finite_differences" and scene.get("fd_steps") is not None and not any(
                math.isclose(opts["step"], h) for h in scene["fd_steps"]):
            continue
        note = ""
        m = None
        if spec["method"] == "finite_differences" and subset is not None:
            opts["vertices"] = subset
            sel = torch.zeros(scene["mesh"].verts.shape[0], 3, dtype=torch.bool)
            sel[subset] = True
            m = tuple(sel if n == "verts" else None for n in scene["wrt"])
            note = f"{len(subset)} of {scene['mesh'].verts.shape[0]:,} vertices"
        if spec["method"] == "exact":
            g, ms = ref, exact_ms
        else:
            g, ms = _timed(lambda: image_gradient(*args, method=spec["method"], **common, **opts), repeat)
        err = gradient_error(g, ref, m)
        rows.append(dict(scene=scene["name"], weights=weights_kind, method=spec["method"], family=spec["family"],
                         param=spec["param"], dtype=spec["dtype"], ms=ms, x_exact=ms / exact_ms, rel=err["rel"],
                         cos=err["cos"], abs=err["abs"], note=note))
    return rows


# ----------------------------------------------------------------------------------------------- Mitsuba

_LLVM_PROBE = ("import mitsuba as mi, drjit as dr; mi.set_variant('llvm_ad_rgb'); "
               "x = dr.maximum(mi.Float([1.0, -2.0]), 0.0); dr.eval(x); print(float(dr.sum(x)[0]))")


def _llvm_candidates():
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return [os.environ["DRJIT_LIBLLVM_PATH"]]
    found = [None]                                                           # None: Dr.Jit's own search
    pats = ["/usr/lib/llvm-*/lib/libLLVM.so*", "/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*",
            os.path.expanduser("~/.rustup/toolchains/*/lib/libLLVM.so.*")]
    libs = sorted({p for pat in pats for p in glob.glob(pat) if os.path.getsize(p) > 1 << 20},
                  key=lambda p: [int(x) for x in __import__("re").findall(r"LLVM[-.a-z]*?(\d+)", p)[:1]] or [0],
                  reverse=True)
    return found + libs


def _find_llvm(out=print) -> tuple[str | None, str | None]:
    """(the libLLVM path Dr.Jit works with, None) or (None, why none works); each tried in a subprocess,
    since an LLVM Dr.Jit cannot compile with aborts the process."""
    errors = []
    for path in _llvm_candidates():
        env = dict(os.environ)
        if path:
            env["DRJIT_LIBLLVM_PATH"] = path
        try:
            res = subprocess.run([sys.executable, "-c", _LLVM_PROBE], env=env, capture_output=True, text=True,
                                 timeout=120)
        except subprocess.TimeoutExpired:
            errors.append(f"{path or 'default libLLVM'}: timed out")
            continue
        if res.returncode == 0:
            return path or "", None
        msg = next((ln for ln in (res.stderr + res.stdout).splitlines()
                    if "LLVM ERROR" in ln or "Error" in ln or "error" in ln), f"exit code {res.returncode}")
        errors.append(f"{path or 'default libLLVM'}: {msg.strip()[:160]}")
    return None, "; ".join(errors) or "no libLLVM found"


class _Mitsuba:
    """Mitsuba 3 (llvm_ad_rgb) on one of our scenes: emissive flat-coloured faces, box filter, our camera."""

    def __init__(self):
        import drjit as dr
        import mitsuba as mi
        mi.set_variant("llvm_ad_rgb")
        mi.set_log_level(mi.LogLevel.Error)
        self.mi, self.dr = mi, dr

    def scene(self, mesh, camera, colors):
        import numpy as np
        mi = self.mi
        if camera.orthographic:
            raise ValueError("Mitsuba comparison: perspective cameras only")
        K = camera.K.detach().double()
        W, H = camera.width, camera.height
        if abs(float(K[0, 0] - K[1, 1])) > 1e-9 * float(K[0, 0]) or abs(float(K[0, 2]) - W / 2) > 1e-9 \
                or abs(float(K[1, 2]) - H / 2) > 1e-9:
            raise ValueError("Mitsuba comparison: square pixels and a centred principal point only")
        # ours: x_cam = R x + t, OpenCV axes (+x right, +y down, +z forward); Mitsuba's sensor: +x left, +y up
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = camera.R.detach().double().numpy(), camera.t.detach().double().numpy()
        to_world = np.linalg.inv(M) @ np.diag([-1.0, -1.0, 1.0, 1.0])
        fov = math.degrees(2 * math.atan(H / 2 / float(K[1, 1])))
        props = mi.Properties()
        props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "mesh_attribute", "name": "face_color"}})
        props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}})
        verts = mesh.verts.detach().double().numpy()
        faces = mesh.faces.numpy()
        shape = mi.Mesh("mesh", vertex_count=verts.shape[0], face_count=faces.shape[0], props=props)
        shape.add_attribute("face_color", 3, mi.Float(colors.detach().double().numpy().astype(np.float32).ravel()))
        p = mi.traverse(shape)
        p["vertex_positions"] = mi.Float(verts.astype(np.float32).ravel())
        p["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
        p.update()
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "direct_projective", "sppi": 0}, "shape": shape,
            "sensor": {"type": "perspective", "fov": fov, "fov_axis": "y", "near_clip": float(camera.near),
                       "far_clip": float(camera.far), "to_world": mi.ScalarTransform4f(to_world.tolist()),
                       "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
                                "pixel_format": "rgb"}}})

    def image(self, scene, spp, seed=0):
        import numpy as np
        return torch.from_numpy(np.array(self.mi.render(scene, spp=spp, seed=seed))).double()

    def gradient(self, scene, weights, spp, seed=0):
        """(V, 3) d Σ weights ⊙ image / d verts, one forward and backward at ``spp``."""
        import numpy as np
        mi, dr = self.mi, self.dr
        params = mi.traverse(scene)
        key = next(k for k in params.keys() if k.endswith("vertex_positions"))
        dr.enable_grad(params[key])
        params.update()
        wt = mi.TensorXf(weights.detach().numpy().astype(np.float32))
        img = mi.render(scene, params, spp=spp, seed=seed)
        dr.backward(dr.sum(img * wt, axis=None))
        g = torch.from_numpy(np.array(dr.grad(params[key]))).double().reshape(-1, 3)
        dr.disable_grad(params[key])
        return g


def _mitsuba(out=print):
    """A ``_Mitsuba`` or None (with the reason printed)."""
    import importlib.util
    if importlib.util.find_spec("mitsuba") is None:                         # don't import: LLVM is chosen first
        out("--vs mitsuba: skipped, Mitsuba 3 is not installed (pip install 'mitsuba>=3', the bench extra)")
        return None
    if "drjit" in sys.modules and not os.environ.get("DRJIT_LIBLLVM_PATH"):
        out("--vs mitsuba: note, Dr.Jit was imported before its libLLVM could be chosen")
    path, why = _find_llvm(out)
    if path is None:
        out(f"--vs mitsuba: skipped, Dr.Jit's LLVM backend (llvm_ad_rgb, the AD variant on CPU) does not work "
            f"here: {why}. Set DRJIT_LIBLLVM_PATH to a libLLVM that Dr.Jit can compile with.")
        return None
    if path:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    try:
        m = _Mitsuba()
    except Exception as err:                                                 # noqa: BLE001
        out(f"--vs mitsuba: skipped, {type(err).__name__}: {err}")
        return None
    out(f"Mitsuba {m.mi.__version__} (Dr.Jit {m.dr.__version__}), variant llvm_ad_rgb, libLLVM "
        f"{path or '(Dr.Jit default)'}")
    return m


def _mitsuba_geometry_check(m, out=print, spp=1024) -> bool:
    """Mitsuba's image of the triangle scene against exact_coverage: they must agree to Monte Carlo noise."""
    sc = make_scene("triangle")
    ref = exact_coverage(sc["mesh"], sc["camera"], sc["colors"])
    img = m.image(m.scene(sc["mesh"], sc["camera"], sc["colors"]), spp, seed=1)
    diff = (img - ref).abs()
    flipped = (img.flip(0).flip(1) - ref).abs().mean()
    # the noise of a pixel an edge crosses is at most 0.5 colour / sqrt(spp); mean over all pixels far less
    ok = float(diff.max()) < 6 * 0.5 / math.sqrt(spp) and float(diff.mean()) < 0.1 * float(flipped)
    out(f"Mitsuba geometry check, triangle at 32², {spp} spp: max |Mitsuba - exact_coverage| = "
        f"{float(diff.max()):.2e}, mean {float(diff.mean()):.2e} (image flipped: mean {float(flipped):.2e}) -> "
        f"{'agree to Monte Carlo noise' if ok else 'DISAGREE: Mitsuba gradients not compared'}")
    return ok


def mitsuba_rows(m, scene, weights_kind, spps=MITSUBA_SPP, repeat=REPEAT, out=print) -> list[dict]:
    """Mitsuba's direct_projective vertex gradient at each spp on ``scene`` against our exact gradient."""
    if scene["wrt"] != ("verts",) or scene["model"] != "flat" or any(scene["background"]):
        return []
    w = weights_for(scene, weights_kind)
    ref, exact_ms = _timed(lambda: image_gradient(scene["mesh"], scene["camera"], scene["colors"], w,
                                                  method="exact"), repeat)
    variants = [("Mitsuba proj. (f32)", scene["colors"], ref, exact_ms, "direct_projective")]
    comp = _components(scene["mesh"].faces)
    if int(comp.max()) + 1 < comp.numel():
        # projective sampling differentiates geometric silhouettes and occlusion, not jumps of emission between
        # faces that share an edge: with one colour per object those jumps are gone, and the two must agree
        col = torch.stack([scene["colors"][comp == k].mean(0) for k in range(int(comp.max()) + 1)])[comp]
        ref1, ms1 = _timed(lambda: image_gradient(scene["mesh"], scene["camera"], col, w, method="exact"), repeat)
        variants.append(("Mitsuba 1 col/object", col, ref1, ms1, "vs exact with 1 colour/object"))
    rows = []
    for family, colors, r, ems, note in variants:
        msc = m.scene(scene["mesh"], scene["camera"], colors)
        for spp in spps:
            m.gradient(msc, w, spp, seed=99)                                # compile the kernels first
            g, ms = _timed(lambda: m.gradient(msc, w, spp, seed=spp), repeat)
            err = gradient_error((g,), (r,))
            rows.append(dict(scene=scene["name"], weights=weights_kind, method="mitsuba", family=family,
                             param=f"{spp} spp", dtype="float32", ms=ms, x_exact=ms / ems, rel=err["rel"],
                             cos=err["cos"], abs=err["abs"], note=note))
    return rows


def _components(faces) -> torch.Tensor:
    """(F,) the connected component (faces sharing vertices) of each face, numbered from 0."""
    label = torch.arange(int(faces.max()) + 1)
    while True:
        low = label[faces].min(1).values                                    # each face: its smallest label
        new = label.scatter_reduce(0, faces.reshape(-1), low.repeat_interleave(3), "amin")
        new = new[new]                                                      # pointer jumping
        if torch.equal(new, label):
            break
        label = new
    return torch.unique(label[faces[:, 0]], return_inverse=True)[1]


# ----------------------------------------------------------------------------------------- table and plot

def format_table(rows) -> str:
    head = (f"{'scene':<10}{'weights':<8}{'method':<22}{'setting':<13}{'dtype':<8}{'ms':>10}{'× exact':>9}"
            f"{'rel L2':>14}{'cosine':>11}  note")
    lines = [head, "-" * len(head)]
    for r in rows:
        rel = f"{r['rel']:>10.2e}{' abs' if r['abs'] else '    '}" if not math.isnan(r["rel"]) else f"{'-':>14}"
        cos = f"{r['cos']:>11.6f}" if not math.isnan(r["cos"]) else f"{'-':>11}"
        lines.append(f"{r['scene']:<10}{r['weights']:<8}{r['family']:<22}{r['param']:<13}{r['dtype']:<8}"
                     f"{r['ms']:>10.1f}{r['x_exact']:>9.2f}{rel}{cos}  {r['note']}")
    return "\n".join(lines)


def plot_pareto(rows, path=None):
    """Log-log: time (ms, forward + gradient) against relative L2 error to the exact gradient, a panel per
    (scene, weights), four to a row, a line per method family (edge sampling, FD float64, ..., Mitsuba), each
    point labelled with its setting; the exact gradient's own time as a dashed vertical line (lecture 09's figure,
    ``course.viz.plot_error_cost``, with each row's own time). rows: ``bench_gradients`` rows. path: where to
    save it (None: don't). Returns the matplotlib figure. Raises ValueError on no rows."""
    from ..viz.gradients import plot_error_cost
    rows = list(rows)
    if not rows:
        raise ValueError("plot_pareto: no rows to plot")
    panels = {}
    for r in rows:
        panels.setdefault(f"{r['scene']}, {r['weights']} weights", []).append(r)
    fig = plot_error_cost(panels, cols=4, whole_gradient=False)
    if path:
        fig.savefig(path, dpi=110)
    return fig


NOTE = """\
rel L2: ‖g - g*‖ / ‖g*‖ over every entry, g* the exact gradient ("abs": g* = 0 there, the absolute error ‖g‖);
  pose row: the largest over R, t, focal. cosine: of g and g* (pose: each parameter's block scaled to unit g*).
× exact: the method's time (forward + gradient, one image_gradient call) over the exact gradient's on the same
  row; below 1 it is cheaper than differentiating the closed form, above 1 dearer.
reparameterization: the bounded warp (course.warp), "spp" samples per pixel that holds a jump (every pixel with
  vertex colours); unbiased, its divergence bounded. "harmonic": the inverse-distance warp, unbiased too, whose
  divergence grows like 1/r where a jump meets a pixel's border or two jumps moving differently meet.
FD: central differences of the closed-form image in the dtype shown (float32: round-off eps/h swamps it);
  "k of V vertices": a fixed seeded subset of the vertices the loss depends on, error over those entries.
soft, NMR: gradients of a different image (blurred, or hard with NMR's approximation), not estimators of this one."""


def bench_gradients(scenes=DEFAULT_SCENES, weights=WEIGHTS, repeat: int = REPEAT, samples=SAMPLES, sigmas=SIGMAS,
                    steps=None, fd_vertices: int = FD_VERTICES, plot: str | None = "gradients_pareto.png",
                    vs=None, mitsuba_spp=MITSUBA_SPP, out=print, warp_samples=WARP_SAMPLES) -> list[dict]:
    """Every method on every scene and kind of weights: prints the table and the note, writes the plot;
    returns the rows (dicts: scene, weights, method, family, param, dtype, ms, x_exact, rel, cos, abs, note)."""
    m = None
    if vs == "mitsuba":
        m = _mitsuba(out)
        if m is not None and not _mitsuba_geometry_check(m, out):
            m = None
    rows = []
    specs = method_specs(steps, samples, sigmas, warp_samples=warp_samples)
    for name in scenes:
        sc = make_scene(name)
        missing = _model_missing(sc["model"])
        if missing:
            out(f"{name}: skipped, model={sc['model']!r}: {missing}")
            continue
        out(f"{name}: {sc['label']}; float64 unless float32 is shown")
        for kind in weights:
            block = measure_scene(sc, kind, specs, repeat, fd_vertices, out)
            if m is not None:
                block += mitsuba_rows(m, sc, kind, mitsuba_spp, repeat, out)
            rows += block
    out(format_table(rows))
    out(NOTE)
    if plot and rows:
        plot_pareto(rows, plot)
        out(f"\nPareto plot written to {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=None,
                        help=f"scenes (default: {' '.join(DEFAULT_SCENES)}; S1 only here or with --full)")
    parser.add_argument("--full", action="store_true", help="every scene, S1 at 512² included (minutes)")
    parser.add_argument("--weights", nargs="+", choices=WEIGHTS, default=list(WEIGHTS), help="kinds of weights")
    parser.add_argument("--samples", nargs="+", type=int, default=list(SAMPLES), help="edge-sampling sample counts")
    parser.add_argument("--warp-samples", nargs="+", type=int, default=list(WARP_SAMPLES),
                        help="reparameterization: samples per pixel that holds a jump")
    parser.add_argument("--sigmas", nargs="+", type=float, default=list(SIGMAS), help="soft rasterization σ (NDC)")
    parser.add_argument("--fd-vertices", type=int, default=FD_VERTICES,
                        help=f"finite differences on meshes of more than {FD_ALL_VERTICES} vertices: this many "
                             "seeded vertices")
    parser.add_argument("--plot", default="gradients_pareto.png", help="where to save the Pareto plot ('' for none)")
    parser.add_argument("--vs", choices=["mitsuba"], help="also Mitsuba 3's direct_projective (the bench extra)")
    parser.add_argument("--mitsuba-spp", nargs="+", type=int, default=list(MITSUBA_SPP),
                        help="Mitsuba samples per pixel")


def run(args) -> list[dict]:
    scenes = SCENES if args.full else (args.scenes or DEFAULT_SCENES)
    return bench_gradients(scenes, args.weights, args.repeat, args.samples, args.sigmas, None, args.fd_vertices,
                           args.plot or None, args.vs, args.mitsuba_spp, warp_samples=args.warp_samples)
