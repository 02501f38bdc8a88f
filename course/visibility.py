"""Visibility gradients: the derivative of a box-filtered image, by every method of lecture 09, side by side.

The quantity. Each pixel of the box-filtered image is the integral of the scene's colour over the pixel's
unit square; a loss ``L = Σ weights ⊙ image`` is a number, and ``image_gradient`` returns dL/dπ for the
parameters π: the mesh's vertices, the camera's R, t and focal length, the colours.

Why it is hard. Inside a face the colour is smooth in π, but where one face meets another (or the
background) it jumps, and the jump moves when π moves. Differentiating under the integral misses that:
``d/dπ ∫_A f ≠ ∫_A ∂f/∂π`` when f jumps. The Reynolds transport theorem gives the missing part, a boundary
integral: for a pixel square A split into regions of colour c_k,

    d/dπ ∫_A f dx = ∫_A ∂f/∂π dx + Σ_boundaries ∫ (c_in - c_out) v_n ds,

with v_n the speed at which the boundary moves along its outward normal (from the "in" region into the
"out" one). With flat-coloured faces (``model="flat"``) the first term is zero: everything is boundary.

The methods (``method=``), each a function of this module:

* ``"exact"``: autograd through the closed-form image (``coverage.exact_coverage``: every pixel as a sum
  of visible polygon areas), chunk by chunk so that memory stays bounded. The ground truth.
* ``"finite_differences"``: ``(L(π + h) - L(π - h)) / 2h`` (``scheme="central"``) or the forward
  difference, one parameter at a time, on the closed-form image in ``dtype``. A vertex moves only the pixels
  its faces touch, so only those are evaluated again (a crop of the camera). On large meshes pass
  ``vertices=`` (a seeded subset): the other entries come back as NaN, not computed.
* ``"reynolds"``: the boundary integral, by Gauss-Legendre quadrature of ``order`` points on every piece of
  every edge between two pixel borders. At each point the visible face just inside and just outside the
  edge (one sample of the z-buffer on each side) says whether the edge is a boundary there and what jumps.
* ``"edge_sampling"`` (Li, Aittala, Durand and Lehtinen, SIGGRAPH Asia 2018): the same integrand at
  ``samples`` random points on the edges, chosen with probability proportional to their length. Unbiased;
  its variance falls as 1 / samples.
* ``"reparameterization"``: change the variables of each pixel's integral so that the jumps stay put
  (``course.warp``: a warp field continuous over the pixel, equal to the jumps' normal speed on them and
  with no normal part on the pixel's border), then differentiate under the integral at ``samples`` stratified
  points per pixel. Unbiased: ``warp="bounded"`` (the default: each constraint met as strongly as the point is
  near it, a least-squares warp whose divergence stays bounded) and ``warp="harmonic"`` (Bangaru, Li and
  Durand's warped-area sampling in its simplest form: its divergence grows like 1/r where a jump meets the
  pixel's border, and a run's error with it); ``warp="nearest"`` follows one jump per point, as Loubet,
  Holzschuch and Jakob's estimator, and is biased where two share a pixel.
* ``"nmr"`` and ``"soft"``: the gradients of lecture 08, of a different image (the hard one, or a blurred
  one): ``nmr.nmr_rasterize`` and ``soft.soft_rasterize``. They are here to be compared, not because they
  estimate this derivative.

Two image models (``model=``): ``"flat"``, one colour per face (``coverage.exact_coverage``: everything is
boundary), and ``"affine"``, vertex colours interpolated affinely on screen (``coverage_affine``: each
piece's area times the colour at its centroid). With affine colours the interior term is autograd under
fixed pieces (``boundary._interior``), and the boundary integrand is the product of two linear functions along a
piece: exact with ``order=2``, not with 1.

What "equal" covers. ``exact``, ``reynolds`` (and the means of ``edge_sampling`` and ``reparameterization``)
compute the same number, to rounding (about 1e-12 relative in float64), on every scene the tests know: meshes
closed or open, faces that pass through each other (the crossing ending on an open boundary, at a corner, or
through a shared vertex), faces clipped by the near plane, seams, and scenes with kinks: where a line of the
scene lies exactly on a pixel border or a vertex on a pixel corner, each pixel's derivative depends on the
direction of the motion, and every boundary method returns the one-sided derivative for the scene moving a hair
toward +x, +y on screen (the half-open pixels [j, j+1) of the conventions). Reparameterization is not made for
kinks (its warp holds every pixel's border still, and a jump lying along the border cannot be followed there):
its tests use scenes without them. ``finite_differences`` agree with them where the image is
differentiable, to their own error (about 1e-9 relative at step 1e-5 in float64); at a kink central
differences return the average of the two sides. A float32 problem gets the float64 answer of its float32
numbers from the boundary methods; ``exact`` cuts its pieces in float32 (about 1e-6 relative). They are not
equal where faces become exactly coplanar or edge-on (the derivative there is the arrangement's, one side's),
nor is ``rasterize``'s z-buffer the same on surfaces closer than float32 resolves (its docstring).

The gradient of a position. Meshes store some positions twice (a seam: one vertex per uv or normal), and
moving one copy alone opens a crack, a motion no surface makes. ``image_gradient`` treats the copies of a
position (equal to 1e-9 of the mesh's size, ``boundary._weld``) as one point: each copy's entry is the
derivative of moving the point, all its copies together, by every method (finite differences move them all).
An optimiser that steps along it keeps the copies together.

A camera batch (one mesh, a list of cameras, weights (N, H, W, 3)): the gradient of the sum over the views,
by "reynolds" or "edge_sampling" in one call (``boundary_gradient`` of the views' ``_Problem``s: the per-mesh
work once, each view's edges and samples, one autograd pass).

The boundary machinery (the edges on screen, their visible pieces, the z-buffer asked beside them, the
interior term of affine colours) lives in ``course.boundary``; this module is the front door and the
methods that differentiate whole images.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch

from .boundary import _weld, boundary_gradient, boundary_points
from .camera import Camera
from .coverage import _region_chunks, exact_coverage
from .coverage_affine import _Field, exact_affine_coverage, polygon_centroids
from .discontinuities import _color_keys
from .raster import _check_inputs, _check_views, interpolate, rasterize
from .nmr import nmr_image, nmr_rasterize
from .soft import soft_rasterize
from .tensors import _check_count, as_tensor
from .warp import WARPS, warp_gradient

__all__ = ["image_gradient", "METHODS", "PARAMETERS", "boundary_points", "boundary_gradient"]

METHODS = ("exact", "finite_differences", "edge_sampling", "reynolds", "reparameterization", "nmr", "soft")
PARAMETERS = ("verts", "R", "t", "focal", "colors")
OPTIONS = {"exact": (), "finite_differences": ("step", "scheme", "vertices"), "reynolds": ("order",),
           "edge_sampling": ("samples", "seed", "generator"), "nmr": ("reach",),
           "reparameterization": ("samples", "kernel", "warp", "seed", "generator"),
           "soft": ("sigma", "gamma", "threshold")}                         # the options of each method


def _count(x, name, most, minimum=1):
    """x as an int >= minimum (and <= most): ``tensors._check_count``, with an upper bound."""
    x = _check_count(x, name, minimum=minimum)
    if most is not None and x > most:
        raise ValueError(f"{name} must be an integer between {minimum} and {most}, got {x}")
    return x


# ------------------------------------------------------------------------------------ parameters

class _Problem:
    """The inputs of ``image_gradient``, checked, with the parameters as leaf tensors that require grad.
    One camera's; a camera batch is a list of them (``batch``), one per view, sharing the mesh's part."""

    def __init__(self, mesh, camera, colors, weights, background, model, dtype=None):
        verts, faces = _check_inputs(mesh, camera)
        if model not in ("flat", "affine"):
            raise ValueError(f"model must be 'flat' (face colours) or 'affine' (vertex colours interpolated "
                             f"affinely on screen), got {model!r}")
        self.model = model
        self.dtype = dtype or torch.promote_types(verts.dtype, camera.dtype)
        dev = verts.device
        c = as_tensor(colors, device=dev, name="colors")
        n, kind = (faces.shape[0], "F, 3) face") if model == "flat" else (verts.shape[0], "V, 3) vertex")
        if c.shape != (n, 3):
            raise ValueError(f"colors must be ({kind} colours for model={model!r}, {kind[0]} = {n}, got "
                             f"{tuple(c.shape)}")
        w = as_tensor(weights, device=dev, name="weights")
        if w.shape != (camera.height, camera.width, 3):
            raise ValueError(f"weights must have shape (H, W, 3) = ({camera.height}, {camera.width}, 3), got "
                             f"{tuple(w.shape)}")
        bg = as_tensor(background, device=dev, name="background")
        if bg.shape != (3,):
            raise ValueError(f"background must have shape (3,), got {tuple(bg.shape)}")
        for name, x in (("colors", c), ("weights", w), ("background", bg)):
            if not torch.isfinite(x).all():
                raise ValueError(f"{name} contains NaN or inf")
        self.faces, self.camera0 = faces, camera
        self.weights, self.background = w.to(self.dtype), bg.to(self.dtype)
        self.weld = _weld(verts)                                            # (V,) one id per position
        self.n_points = int(self.weld.max()) + 1 if self.weld.numel() else 0
        self.params = {"verts": verts.detach().to(self.dtype), "R": camera.R.detach().to(self.dtype),
                       "t": camera.t.detach().to(self.dtype), "focal": camera.K[0, 0].detach().to(self.dtype),
                       "colors": c.detach().to(self.dtype)}
        self.shared = {}                                                    # per-mesh results (``boundary``)

    @classmethod
    def batch(cls, mesh, cameras, colors, weights, background, model, dtype=None) -> list:
        """The problems of a camera batch: cameras a list of N ``Camera``s of one image size, weights
        (N, H, W, 3), one image of weights each. The first is checked in full, the others are its ``view``s."""
        verts, _, cameras, _ = _check_views(mesh, cameras)
        N, H, W = len(cameras), cameras[0].height, cameras[0].width
        w = as_tensor(weights, device=verts.device, name="weights")
        if w.shape != (N, H, W, 3):
            raise ValueError(f"weights must have shape (N, H, W, 3) = ({N}, {H}, {W}, 3) for {N} cameras of "
                             f"{W}x{H}, got {tuple(w.shape)}")
        if not torch.isfinite(w).all():
            raise ValueError("weights contains NaN or inf")
        if dtype is None:                                                   # promote(verts, every camera)
            dtype = verts.dtype
            for c in cameras:
                dtype = torch.promote_types(dtype, c.dtype)
        first = cls(mesh, cameras[0], colors, w[0], background, model, dtype)
        return [first] + [first.view(c, w[k]) for k, c in enumerate(cameras[1:], 1)]

    def view(self, camera, weights) -> "_Problem":
        """The problem of another camera of a batch, weights (H, W, 3) its image's: the same mesh, colours and
        background, the same per-mesh work (``weld``, ``shared``: computed once for all the views)."""
        prob = copy.copy(self)
        prob.camera0, prob.weights = camera, weights.to(self.dtype)
        prob.params = dict(self.params, R=camera.R.detach().to(self.dtype), t=camera.t.detach().to(self.dtype),
                           focal=camera.K[0, 0].detach().to(self.dtype))
        return prob

    def leaves(self, names, like=None):
        """Fresh copies of the parameters, those in ``names`` requiring grad. The vertices are
        ``verts + shift[weld]``: one shift (U, 3), a leaf, per welded position (``boundary._weld``), so that
        the copies of a position (a seam) move together, as one point. like: the leaves of another view of a
        batch, whose mesh leaves (verts, its shift, colors) these share: only R, t and focal are new."""
        if like is not None:
            return dict(like, **{k: self.params[k].clone().requires_grad_(k in names) for k in ("R", "t", "focal")})
        p = {k: v.clone().requires_grad_(k in names) for k, v in self.params.items() if k != "verts"}
        verts = self.params["verts"]
        if "verts" in names:
            p["shift"] = verts.new_zeros(self.n_points, 3).requires_grad_(True)
            p["verts"] = verts + p["shift"][self.weld]
        else:
            p["verts"] = verts.clone()
        return p

    def targets(self, p, names):
        """The leaves to differentiate for ``names``: the welded shift stands for "verts"."""
        return [p["shift"] if n == "verts" else p[n] for n in names]

    def gradients(self, grads, targets, names):
        """Gradients w.r.t. ``targets`` (None: zero) → one per name, in the parameters' dtype; "verts" gets
        each copy of a position the derivative of moving the position (all its copies)."""
        out = []
        for n, g, x in zip(names, grads, targets):
            g = torch.zeros_like(x) if g is None else g.to(x.dtype)
            out.append(g[self.weld] if n == "verts" else g)
        return tuple(out)

    def camera(self, p, crop=None):
        """The camera of the parameters p; ``crop`` (x0, y0, w, h) keeps only those pixels."""
        K0 = self.camera0.K.detach().to(p["focal"].dtype)                  # the parameters' dtype (float64 in boundary)
        scale = p["focal"] / K0[0, 0]                                       # fx and fy scale together
        K = torch.cat([K0[:2] * scale, K0[2:]])
        W, H = self.camera0.width, self.camera0.height
        if crop is not None:
            x0, y0, W, H = crop
            K = K - torch.tensor([[0.0, 0, x0], [0, 0, y0], [0, 0, 0]], dtype=K.dtype, device=K.device)
        return Camera(K, p["R"], p["t"], W, H, self.camera0.near, self.camera0.far, self.camera0.orthographic)

    def mesh(self, p):
        return _Mesh(p["verts"], self.faces)


class _Mesh:
    def __init__(self, verts, faces):
        self.verts, self.faces = verts, faces


# -------------------------------------------------------------------------------------- exact

def exact_gradient(prob: _Problem, names):
    """Autograd through ``exact_coverage``, one chunk of pixels at a time: L is a sum over chunks, so each
    chunk's part is differentiated and let go (the per-face geometry's graph is kept between them)."""
    p = prob.leaves(names)
    cam, mesh = prob.camera(p), prob.mesh(p)
    w = prob.weights.reshape(-1, 3)
    colors = p["colors"] - prob.background                                   # image = bg + Σ area (c - bg)
    field = _Field(mesh.verts, mesh.faces, cam) if prob.model == "affine" else None
    leaves = prob.targets(p, names)
    total = [torch.zeros_like(x) for x in leaves]
    keys = None                                                             # pixels of one colour all over
    if field is None and "colors" not in names:                             # need no clipping (coverage)
        keys = _color_keys(prob.params["colors"])
    for regions in _region_chunks(mesh.verts, mesh.faces, cam, prob.dtype, keys):
        if regions.pixel.numel() == 0:
            continue
        if field is None:
            c = colors[regions.face]
        else:                                                               # the colour at the centroid
            field.check(torch.unique(regions.face), "image_gradient")
            c = field.colors(regions.face, regions.pixel, polygon_centroids(regions.verts, regions.count), colors)
        part = (w[regions.pixel] * regions.area[:, None] * c).sum()
        if not part.requires_grad:
            continue
        g = torch.autograd.grad(part, leaves, retain_graph=True, allow_unused=True)
        total = [a + (b if b is not None else 0) for a, b in zip(total, g)]
    return prob.gradients(total, leaves, names)


# ---------------------------------------------------------------------------- finite differences

def _loss(prob, p, crop=None):
    w = prob.weights
    if crop is not None:
        x0, y0, W, H = crop
        w = w[y0:y0 + H, x0:x0 + W]
    image = (exact_coverage if prob.model == "flat" else exact_affine_coverage)(
        prob.mesh(p), prob.camera(p, crop), p["colors"], prob.background)
    return (w * image).sum()


def _reach(prob, p, vertex, step):
    """The pixels a move of ``vertex`` by up to ``step`` can change: the box around the projections of its
    faces (one pixel of margin, and the vertex moved by ±step), clipped to the image; None if none."""
    faces = prob.faces[(prob.weld[prob.faces] == prob.weld[vertex]).any(1)]   # its copies' faces too
    if faces.numel() == 0:
        return None
    cam = prob.camera(p)
    v = p["verts"].detach()[faces.reshape(-1)]
    moved = [v]
    for sgn in (1.0, -1.0):
        for axis in range(3):
            d = torch.zeros_like(v)
            d[:, axis] = sgn * step
            moved.append(v + d)
    xy, depth = cam.project(torch.cat(moved))
    if (depth <= cam.near).any() or not torch.isfinite(xy).all():
        return (0, 0, cam.width, cam.height)                                # near plane: the whole image
    x0 = max(int(math.floor(float(xy[:, 0].min()))) - 1, 0)
    y0 = max(int(math.floor(float(xy[:, 1].min()))) - 1, 0)
    x1 = min(int(math.ceil(float(xy[:, 0].max()))) + 1, cam.width)
    y1 = min(int(math.ceil(float(xy[:, 1].max()))) + 1, cam.height)
    if x1 <= x0 or y1 <= y0:
        return None
    return (x0, y0, x1 - x0, y1 - y0)


def fd_gradient(prob: _Problem, names, step=1e-4, scheme="central", vertices=None):
    """Finite differences of L, one parameter entry at a time, in the problem's dtype (see module docstring)."""
    if scheme not in ("central", "forward"):
        raise ValueError(f"scheme must be 'central' or 'forward', got {scheme!r}")
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not (0 < step < math.inf):
        raise ValueError(f"step must be a positive finite number, got {step!r}")
    if vertices is not None:                                                # a list of vertex indices
        flat = vertices.reshape(-1) if torch.is_tensor(vertices) else np.asarray(vertices).reshape(-1)
        listed = flat.tolist()
        vertices = [_count(i, "vertices (each entry, a vertex index)", None, minimum=0) for i in listed]
    out = []
    with torch.no_grad():
        base = prob.leaves(())
        for name in names:
            x = base[name]
            g = torch.full_like(x, math.nan) if name == "verts" and vertices is not None else torch.zeros_like(x)
            if name == "verts":
                ids = range(x.shape[0]) if vertices is None else [int(i) for i in vertices]
                if any(not 0 <= i < x.shape[0] for i in ids):
                    raise ValueError(f"vertices must be indices in [0, {x.shape[0]}), got {list(vertices)}")
                entries = [(i, a) for i in ids for a in range(3)]
            else:
                entries = list(np.ndindex(*x.shape)) if x.dim() else [()]
            for e in entries:
                crop = None
                if name == "verts":
                    crop = _reach(prob, base, e[0], step)
                    if crop is None:
                        g[e] = 0.0
                        continue
                def at(delta):
                    p = dict(base)
                    y = x.clone()
                    if name == "verts":                                     # the position: all its copies
                        copies = prob.weld == prob.weld[e[0]]
                        y[copies, e[1]] = y[copies, e[1]] + delta
                    else:
                        y[e] = y[e] + delta
                    p[name] = y
                    return _loss(prob, p, crop)
                if scheme == "central":
                    g[e] = (at(step) - at(-step)) / (2 * step)
                else:
                    g[e] = (at(step) - at(0.0)) / step
            out.append(g)
    return tuple(out)


# ------------------------------------------------------------------------------- NMR and soft (lecture 08)

def _other_image_gradient(prob, names, render):
    p = prob.leaves(names)
    image = render(prob.mesh(p), prob.camera(p), p["colors"], prob.background)
    loss = (prob.weights * image).sum()
    leaves = prob.targets(p, names)
    g = torch.autograd.grad(loss, leaves, allow_unused=True) if loss.requires_grad else (None,) * len(leaves)
    return prob.gradients(g, leaves, names)


# ------------------------------------------------------------------------------------- the front door

def _generator(options):
    """The random numbers of the sampling methods: ``generator``, or a fresh one seeded with ``seed`` (0)."""
    generator, seed = options.pop("generator", None), options.pop("seed", 0)
    if generator is None:
        return torch.Generator().manual_seed(_count(seed, "seed", None, minimum=0))
    if not isinstance(generator, torch.Generator):
        raise ValueError(f"generator must be a torch.Generator, got {type(generator).__name__}")
    return generator


def image_gradient(mesh, camera, colors, weights, *, method, model="flat", background=(0.0, 0.0, 0.0),
                   wrt=None, **options):
    """The gradient of ``L = Σ weights ⊙ image`` (the box-filtered image) by one method of lecture 09.

    mesh: ``verts`` (V, 3), ``faces`` (F, 3); camera: a ``Camera`` (perspective or orthographic); colors: (F, 3)
    face colours (``model="flat"``); weights: (H, W, 3); background: (3,). method: one of ``METHODS`` (module
    docstring). wrt: None for d L / d mesh.verts, (V, 3); or a sequence of ``PARAMETERS`` names ("verts", "R",
    "t", "focal" (K[0, 0], with K[1, 1] scaled along), "colors"), and a tuple comes back in that order.
    A camera batch: camera a list of N cameras of one image size and weights (N, H, W, 3), for the gradient
    of ``Σ_views Σ weights ⊙ image`` by "reynolds" or "edge_sampling" (``boundary_gradient``: the per-mesh
    work done once, one autograd pass; ``samples`` points per view, drawn view after view from one
    generator); "verts" and "colors" come back summed over the views, "R" (N, 3, 3), "t" (N, 3) and "focal"
    (N,) one per view. The other methods take one camera at a time.
    Copies of one position (a seam) get the same entry, the derivative of moving them all (module docstring).
    options: ``dtype`` (every method; default promote(verts, camera)); finite_differences: ``step`` (1e-4),
    ``scheme`` ("central" / "forward"), ``vertices`` (indices; other vertices' entries are NaN);
    reynolds: ``order`` (Gauss points per pixel piece of edge, 1); edge_sampling: ``samples`` (1000),
    ``generator`` or ``seed``; reparameterization: ``samples`` (per pixel, 16), ``kernel`` (pixels, 1.0; None:
    no limit), ``warp`` ("bounded" / "harmonic" / "nearest"), ``generator`` or ``seed``; soft: ``sigma`` (1e-4), ``gamma``
    (1e-4), ``threshold``; nmr: ``reach``.
    """
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if isinstance(wrt, str):
        raise ValueError(f"wrt must be a sequence of names such as ('verts', 't'), got the string {wrt!r}")
    names = ("verts",) if wrt is None else tuple(wrt)
    bad = [n for n in names if not isinstance(n, str) or n not in PARAMETERS]
    if bad or not names or len(set(names)) != len(names):
        raise ValueError(f"wrt must name some of {', '.join(PARAMETERS)}, each once, got {wrt!r}")
    unknown = sorted(set(options) - {"dtype"} - set(OPTIONS[method]))
    if unknown:
        allowed = ", ".join(("dtype",) + OPTIONS[method])
        raise TypeError(f"unexpected options for method={method!r}: {', '.join(unknown)} (it takes {allowed})")
    dtype = options.pop("dtype", None)
    if dtype is not None and not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise ValueError(f"dtype must be a floating torch.dtype such as torch.float32 or torch.float64, got {dtype!r}")
    if isinstance(camera, (list, tuple)):
        if method not in ("reynolds", "edge_sampling"):
            raise ValueError(f"a camera batch takes method 'reynolds' or 'edge_sampling', got {method!r}: call "
                             "image_gradient once per camera and add the gradients")
        prob = _Problem.batch(mesh, camera, colors, weights, background, model, dtype)
    else:
        prob = _Problem(mesh, camera, colors, weights, background, model, dtype)
    if method == "exact":
        grads = exact_gradient(prob, names)
    elif method == "finite_differences":
        grads = fd_gradient(prob, names, **options)
    elif method in ("reynolds", "edge_sampling", "reparameterization"):
        geo = [n for n in names if n != "colors"]
        if method == "reynolds":
            g = boundary_gradient(prob, geo, order=_count(options.pop("order", 1), "order", 64))
        elif method == "edge_sampling":
            g = boundary_gradient(prob, geo, samples=_count(options.pop("samples", 1000), "samples", None),
                                  generator=_generator(options))
        else:
            kernel, warp = options.pop("kernel", 1.0), options.pop("warp", "bounded")
            if kernel is not None and (isinstance(kernel, bool) or not isinstance(kernel, (int, float))
                                       or not 0 < kernel < math.inf):
                raise ValueError(f"kernel must be a positive number of pixels (or None: no limit), got {kernel!r}")
            if warp not in WARPS:
                raise ValueError(f"warp must be one of {', '.join(WARPS)}, got {warp!r}")
            g = warp_gradient(prob, geo, samples=_count(options.pop("samples", 16), "samples", None),
                              kernel=kernel, warp=warp, generator=_generator(options))
        by_name = dict(zip(geo, g))
        if "colors" in names:                                               # linear: the exact derivative
            by_name["colors"] = sum(exact_gradient(q, ("colors",))[0]      # (the interior term, exactly)
                                    for q in (prob if isinstance(prob, list) else [prob]))
        grads = tuple(by_name[n] for n in names)
    elif method == "nmr":
        reach = options.pop("reach", None)

        def nmr(m, c, col, bg):
            if prob.model == "flat":
                return nmr_rasterize(m, c, face_colors=col, background=bg, cull_backfaces=False, reach=reach)
            frags = rasterize(m, c)                                         # vertex colours, then NMR's gradient
            image = torch.where(frags.mask[..., None], interpolate(col, frags, m.faces), bg)
            return nmr_image(image, m, c, frags.face_id, background=bg, cull_backfaces=False, reach=reach)
        grads = _other_image_gradient(prob, names, nmr)
    else:
        sigma, gamma = options.pop("sigma", 1e-4), options.pop("gamma", 1e-4)
        threshold = options.pop("threshold", 1e-4)
        key = "face_colors" if prob.model == "flat" else "vertex_colors"
        grads = _other_image_gradient(prob, names, lambda m, c, col, bg: soft_rasterize(
            m, c, mode="color", background=bg, sigma=sigma, gamma=gamma, threshold=threshold,
            cull_backfaces=False, **{key: col}))
    if method in ("nmr", "soft") and options:
        raise TypeError(f"unexpected options for {method}: {', '.join(options)}")
    return grads[0] if wrt is None else grads
