"""2D-to-3D style transfer and DeepDream through the renderer (lecture 11; Kato, Ushiku and Harada, CVPR 2018, §4).

A mesh's vertices and texture are optimised so that images of it, rendered from random views, have the
*texture statistics* of a 2D style image (``course.style``: Gram matrices of seeded random filters), while a
content term keeps the shape, a smoothness term keeps its changes smooth, and a total-variation term keeps the
texture clean:

    L = Σ_views style_loss(G(render(v, T; view)), G(style)) / views + λ_content mean ‖v - v₀‖² / r²
        + λ_smooth mean_edges ‖(v - v₀)_i - (v - v₀)_j‖² / ℓ² + λ_tv TV(T),

with the colour block of the Gram matrices weighted up (``colour_weight``). DeepDream (``deep_dream_mesh``)
drops the style image: it *maximises* how strongly chosen random filters respond to the rendered images, so
patterns those filters like grow on the surface.

The renderer carries gradients to the texture and the vertices (``render_texture``). ``renderer="nmr"``: Kato et
al.'s own renderer, the Neural 3D Mesh Renderer (``course.nmr``, lecture 08): the z-buffer's image, with their
approximate gradient for moving the edges and the silhouette. ``renderer="soft"``: soft rasterization
(``course.soft``; Liu et al. 2019) of the uvs, then the texture looked up at them: the silhouette and every edge
move smoothly under the loss. ``renderer="hard"``: the z-buffer's uvs alone: the texture still gets its gradient,
and the vertices get one through the uvs inside each face, but no silhouette or occlusion boundary is moved on
purpose. Running them from the same seeds is lecture 11's comparison (``course.bench.style``).

Views: ``random_directions`` draws directions uniform on the sphere (uniform in z = cos θ and in the azimuth,
not in the two angles: that would crowd the poles), one camera per direction looking at the mesh's centre.
Every loop is seeded (the views, the filters), so a run is reproducible; everything runs in float64 unless
``dtype`` says otherwise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from ..camera import Camera
from ..mesh import Mesh
from ..nmr import nmr_image
from ..raster import interpolate, rasterize
from ..soft import soft_rasterize
from .features import RandomFeatures, _check_image, style_loss
from ..tensors import _check_count, _check_real
from ..textures import sample_texture

__all__ = ["random_directions", "view_camera", "render_texture", "stylize_mesh", "deep_dream_mesh", "StyleRun",
           "held_out_style_loss", "outline_change", "RENDERERS"]

RENDERERS = ("soft", "nmr", "hard")


def random_directions(n: int, generator: torch.Generator, *, dtype=torch.float64) -> torch.Tensor:
    """(n, 3) unit vectors uniform on the sphere: z uniform in [-1, 1] (Archimedes: equal heights cut equal
    areas), the azimuth uniform in [0, 2π)."""
    n = _check_count(n, "n")
    u = torch.rand(n, 2, generator=generator, dtype=torch.float64)
    z = 2 * u[:, 0] - 1
    phi = 2 * math.pi * u[:, 1]
    r = (1 - z * z).clamp_min(0).sqrt()
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], 1).to(dtype)


def view_camera(direction, center, distance: float, size: int, fov_y: float = 40.0, *, dtype=torch.float64):
    """A camera ``distance`` from ``center`` along ``direction`` (3,), looking at it, image ``size`` x ``size``.
    The up vector is world y, or z for a view straight along y."""
    d = torch.as_tensor(direction, dtype=torch.float64)
    d = d / d.norm()
    c = torch.as_tensor(center, dtype=torch.float64)
    up = (0.0, 0.0, 1.0) if abs(float(d[1])) > 0.99 else (0.0, 1.0, 0.0)
    eye = c + distance * d
    return Camera.look_at(eye.tolist(), c.tolist(), up, fov_y=fov_y, width=size, height=size, dtype=dtype)


def render_texture(verts, faces, uvs, texture, camera, *, renderer="soft", background=(1.0, 1.0, 1.0),
                   sigma=3e-5, gamma=1e-4):
    """(H, W, 3) image of the mesh with a texture (T, T', 3) looked up at the interpolated uvs (V, 2).

    ``"soft"``: soft rasterization of (u, v, 1) as vertex colours over a black background gives α (the third
    channel, the soft coverage) and α × the blended uv; the texture is sampled (``textures.sample_texture``,
    bilinear) at uv / α and composited over the background with α: differentiable in the vertices (through α
    and uv) and the texture. ``"hard"``: the z-buffer's uvs (``rasterize`` + ``interpolate``) and its mask:
    differentiable in the texture, and in the vertices only through the uvs inside each face (the texture slides
    under the pixels; no silhouette or occlusion edge is moved on purpose). ``"nmr"``: the same image, and to
    the vertices also the Neural 3D Mesh Renderer's approximate edge gradient (``nmr.nmr_image``, Kato et al.
    2018; a newly covered pixel takes the colour of the face's nearest pixel along the row or column, as the
    paper's code does): with ``"hard"``'s forward pass, the renderer Kato et al.'s style transfer used."""
    mesh = Mesh(verts, faces)
    bg = torch.as_tensor(background, dtype=verts.dtype)
    if renderer == "soft":
        uv1 = torch.cat([uvs.to(verts.dtype), torch.ones_like(uvs[:, :1], dtype=verts.dtype)], 1)
        out = soft_rasterize(mesh, camera, mode="color", vertex_colors=uv1, background=0.0, sigma=sigma,
                             gamma=gamma)
        alpha = out[..., 2:]
        uv = out[..., :2] / alpha.clamp_min(1e-6)
    elif renderer in ("hard", "nmr"):
        frags = rasterize(mesh, camera)
        alpha = frags.mask[..., None].to(verts.dtype)
        uv = interpolate(uvs.to(verts.dtype), frags, faces)
    else:
        raise ValueError(f"renderer must be one of {', '.join(RENDERERS)}, got {renderer!r}")
    image = sample_texture(texture, uv, "bilinear") * alpha + bg * (1 - alpha)
    if renderer == "nmr":                                                   # Kato et al.'s edge gradient
        image = nmr_image(image, mesh, camera, frags.face_id, background=bg.detach(), cull_backfaces=False)
    return image


@dataclass
class StyleRun:
    """What ``stylize_mesh`` / ``deep_dream_mesh`` return: the final vertices (V, 3) and texture (T, T, 3), the
    loss of every step (its style part, or the activation for DeepDream), and snapshots (step, verts, texture)."""
    verts: torch.Tensor
    texture: torch.Tensor
    losses: torch.Tensor
    snapshots: list = field(default_factory=list)

    def mesh(self, faces) -> Mesh:
        return Mesh(self.verts, faces)


def _style_term(grams, target, colour_weight):
    """The style loss with the colour block (the first) weighted by ``colour_weight``."""
    return colour_weight * style_loss(grams[:1], target[:1]) + style_loss(grams[1:], target[1:])


def _setup(mesh, steps, views, size, seed, renderer, dtype):
    steps, views, size = _check_count(steps, "steps"), _check_count(views, "views"), _check_count(size, "size")
    if renderer not in RENDERERS:
        raise ValueError(f"renderer must be one of {', '.join(RENDERERS)}, got {renderer!r}")
    verts0 = torch.as_tensor(mesh.verts).detach().to(dtype)
    faces = torch.as_tensor(mesh.faces).long()
    if verts0.dim() != 2 or verts0.shape[1] != 3 or not torch.isfinite(verts0).all():
        raise ValueError(f"mesh.verts must be finite (V, 3), got shape {tuple(verts0.shape)}")
    if faces.numel() == 0:
        raise ValueError("the mesh has no faces: nothing to render")
    uvs = getattr(mesh, "uvs", None)
    if uvs is None or tuple(uvs.shape) != (verts0.shape[0], 2):
        raise ValueError("the mesh needs uvs (V, 2) to carry a texture (models.teapot has them)")
    center = (verts0.max(0).values + verts0.min(0).values) / 2
    radius = float((verts0 - center).norm(dim=1).max())
    return (steps, views, size, verts0, faces, uvs.detach().to(dtype), center, radius,
            torch.Generator().manual_seed(int(seed)))


def stylize_mesh(mesh, style, *, steps: int = 60, views: int = 2, size: int = 64, renderer: str = "soft",
                 texture_size: int = 64, colour_weight: float = 10.0, content_weight: float = 20.0,
                 smooth_weight: float = 10.0, tv_weight: float = 4.0, lr_verts: float = 0.001,
                 lr_texture: float = 0.1, geometry: bool = True, seed: int = 0,
                 network: RandomFeatures | None = None, snapshot_every: int | None = None,
                 progress: bool = False, dtype=torch.float64) -> StyleRun:
    """Kato et al.'s 2D-to-3D style transfer: vertex offsets and a texture (``texture_size``², from mid-grey,
    on the mesh's uvs) by Adam, so that ``views`` random views per step, rendered by ``renderer`` ("soft",
    "nmr": the paper's, or "hard"), match ``style`` (H, W, 3)'s random-filter Gram matrices.

    colour_weight: how much more the colour block (mean colour and covariance) counts than each filter block
    (random filters reward contrast, and alone drive the colours to saturation); content_weight: on the mean
    squared vertex offset relative to the mesh's radius (keeps the shape); smooth_weight: on the mean squared
    difference of neighbouring vertices' offsets relative to the mean edge length (the offsets vary smoothly:
    the shape bends rather than crumples); tv_weight: on the texture's total
    variation (mean squared difference of neighbouring texels); geometry: False optimises the texture only.
    The background is the style image's mean colour (it is part of every rendered image's statistics).
    Returns a ``StyleRun`` (``losses``: the style term of each step, colour block weighted, averaged over
    its views)."""
    steps, views, size, verts0, faces, uvs, center, radius, gen = _setup(mesh, steps, views, size, seed, renderer,
                                                                         dtype)
    net = network if network is not None else RandomFeatures(channels=32, seed=seed, dtype=dtype)
    style = _check_image(style, "style")[0].permute(1, 2, 0).to(dtype)
    with torch.no_grad():
        target = [g.detach() for g in net(style)]
    background = style.reshape(-1, 3).mean(0)
    T = _check_count(texture_size, "texture_size")
    offsets = torch.zeros_like(verts0, requires_grad=True)
    logits = torch.zeros(T, T, 3, dtype=dtype, requires_grad=True)         # sigmoid(0) = mid-grey
    edges = _edges(faces)
    spacing = float((verts0[edges[:, 0]] - verts0[edges[:, 1]]).norm(dim=1).mean())   # the mean edge length
    groups = [{"params": [logits], "lr": lr_texture}]
    if geometry:
        groups.append({"params": [offsets], "lr": lr_verts})
    opt = torch.optim.Adam(groups)
    losses, snapshots = [], []
    bar = _progress(steps, progress, "style")
    for step in range(steps):
        opt.zero_grad()
        verts, texture = verts0 + offsets, torch.sigmoid(logits)
        s = 0.0
        for d in random_directions(views, gen):
            cam = view_camera(d, center, 3.2 * radius, size, dtype=dtype)
            image = render_texture(verts, faces, uvs, texture, cam, renderer=renderer, background=background)
            s = s + _style_term(net(image), target, colour_weight) / views
        content = (offsets ** 2).sum(1).mean() / radius ** 2
        bend = ((offsets[edges[:, 0]] - offsets[edges[:, 1]]) ** 2).sum(1).mean() / spacing ** 2
        tv = ((texture[1:] - texture[:-1]) ** 2).mean() + ((texture[:, 1:] - texture[:, :-1]) ** 2).mean()
        loss = s + content_weight * content + smooth_weight * bend + tv_weight * tv
        loss.backward()
        opt.step()
        losses.append(float(s.detach()))
        if snapshot_every and (step % snapshot_every == 0 or step == steps - 1):
            snapshots.append((step, (verts0 + offsets).detach().clone(), torch.sigmoid(logits).detach().clone()))
        bar.update(1)
    bar.close()
    return StyleRun((verts0 + offsets).detach(), torch.sigmoid(logits).detach(), torch.tensor(losses), snapshots)


def deep_dream_mesh(mesh, *, steps: int = 40, views: int = 2, size: int = 64, renderer: str = "soft",
                    block: int = 2, channels=(0, 1, 2, 3), step_size: float = 0.05, geometry: bool = True,
                    texture_size: int = 64, seed: int = 0, network: RandomFeatures | None = None, texture=None,
                    progress: bool = False, dtype=torch.float64) -> StyleRun:
    """DeepDream on a mesh: gradient *ascent* on the mean squared response of ``channels`` of one feature block
    (``block``: an index into ``RandomFeatures.features``, 0 the first (scale, size)), over ``views`` random
    views per step. Each step moves the texture's logits along the gradient divided by its mean absolute
    value, a step of fixed size whatever the gradient's scale (Mordvintsev et al.'s normalisation), and with
    ``geometry`` the vertices along the gradient divided by its largest entry, times ``step_size`` × radius / 10
    (no coordinate moves further than that in one step: radius / 200 by default). texture: the start texture (T, T', 3) in (0, 1)
    (default: ``texture_size``² of mid-grey with seeded noise of σ 0.05: a flat image excites no
    zero-mean filter, so its gradient would be 0). Returns a ``StyleRun`` whose ``losses`` are the activations."""
    steps, views, size, verts0, faces, uvs, center, radius, gen = _setup(mesh, steps, views, size, seed, renderer,
                                                                         dtype)
    net = network if network is not None else RandomFeatures(channels=32, seed=seed, dtype=dtype)
    step_size = _check_real(step_size, "step_size", low=0, low_open=True)
    T = _check_count(texture_size, "texture_size")
    if texture is None:                                                     # grey with a little seeded noise:
        noise = torch.randn(T, T, 3, generator=gen, dtype=torch.float64).to(dtype)   # a flat grey image
        start = 0.5 + 0.05 * noise                                          # excites no zero-mean filter
    else:
        start = torch.as_tensor(texture, dtype=dtype).clamp(1e-3, 1 - 1e-3)
    logits = torch.logit(start).clone().requires_grad_(True)
    offsets = torch.zeros_like(verts0, requires_grad=True)
    params = [logits, offsets] if geometry else [logits]
    acts = []
    bar = _progress(steps, progress, "dream")
    for step in range(steps):
        a = 0.0
        for d in random_directions(views, gen):
            cam = view_camera(d, center, 3.2 * radius, size, dtype=dtype)
            image = render_texture(verts0 + offsets, faces, uvs, torch.sigmoid(logits), cam, renderer=renderer,
                                   background=(0.5, 0.5, 0.5))
            a = a + net.activation(image, block, channels) / views
        grads = torch.autograd.grad(a, params, allow_unused=True)
        with torch.no_grad():                                               # ascent, normalised steps
            if grads[0] is not None:                                        # texture: g / mean |g|
                logits += step_size * grads[0] / grads[0].abs().mean().clamp_min(1e-12)
            if geometry and grads[1] is not None:                           # each coordinate: radius / 200
                offsets += step_size * radius / 10 * grads[1] / grads[1].abs().max().clamp_min(1e-12)
        acts.append(float(a.detach()))
        bar.update(1)
    bar.close()
    return StyleRun((verts0 + offsets).detach(), torch.sigmoid(logits).detach(), torch.tensor(acts))


def held_out_style_loss(mesh, run: StyleRun, style, *, views: int = 8, size: int = 64, seed: int = 123,
                        renderer: str = "hard", colour_weight: float = 10.0,
                        network: RandomFeatures | None = None) -> float:
    """How well a run's result has the style, judged the same way whatever renderer trained it: the style term
    (colour block weighted as in ``stylize_mesh``) of renders by ``renderer`` (the judge: "hard", the z-buffer,
    or "soft") from ``views`` directions of a generator seeded ``seed`` (not the training views), averaged.
    A judge favours results trained through the same renderer (their images are what was optimised): compare
    runs under both. mesh: the mesh the run started from (faces and uvs); network: the run's (seeded 0 when
    None, as ``stylize_mesh``'s default)."""
    net = network if network is not None else RandomFeatures(channels=32, seed=0, dtype=run.verts.dtype)
    style = _check_image(style, "style")[0].permute(1, 2, 0).to(run.verts.dtype)
    faces, uvs = torch.as_tensor(mesh.faces).long(), mesh.uvs.to(run.verts.dtype)
    center = (run.verts.max(0).values + run.verts.min(0).values) / 2
    radius = float((run.verts - center).norm(dim=1).max())
    with torch.no_grad():
        target = net(style)
        total = 0.0
        for d in random_directions(views, torch.Generator().manual_seed(int(seed)), dtype=run.verts.dtype):
            cam = view_camera(d, center, 3.2 * radius, size, dtype=run.verts.dtype)
            image = render_texture(run.verts, faces, uvs, run.texture, cam, renderer=renderer,
                                   background=style.reshape(-1, 3).mean(0))
            total += float(_style_term(net(image), target, colour_weight))
    return total / views


def outline_change(faces, verts0, verts, cameras) -> float:
    """How much the outline moved: ``1 - IoU`` of the z-buffer's silhouettes of ``verts`` and ``verts0``, summed
    over ``cameras``."""
    faces = torch.as_tensor(faces).long()
    total = 0.0
    with torch.no_grad():
        for cam in cameras:
            a = rasterize(Mesh(verts, faces), cam).mask
            b = rasterize(Mesh(verts0, faces), cam).mask
            union = float((a | b).sum())
            total += 1 - float((a & b).sum()) / union if union else 0.0
    return total


def _edges(faces):
    """(E, 2) the mesh's edges, each once."""
    e = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return torch.unique(torch.sort(e, dim=1).values, dim=0)


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(steps, show, label):
    if not show:
        return _NoBar()
    from tqdm.auto import tqdm
    return tqdm(total=steps, desc=label, leave=False)
