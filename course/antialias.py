"""Antialiasing (lecture 05): supersampling, adaptive supersampling, and the exact pixel integral.

A pixel is not a point but a small square, and its colour should be the *average* of the image over that
square (the box filter): ``I_ij = ∫∫_pixel I(x, y) dx dy``. One sample at the centre replaces the integral by
a single point value, which is where jaggies, breaking slivers and flickering come from. Three cures, from
cheap to exact::

    supersample            k × k samples in every pixel, averaged    error ~ 1/k along edges, cost ~ k²
    adaptive_supersample   k × k samples only where a discontinuity  the same samples where it matters,
                           of the image crosses the pixel            one elsewhere
    exact_coverage         the integral in closed form (coverage.py) the ground truth

Every sampler here calls the one rasterizer, ``rasterize(mesh, camera, samples=..., pixels=...)``: a sample's
visible face depends only on its own position, so the adaptive sampler's samples are bit-identical to the
full supersampler's wherever it takes them.

Where does an image of flat-coloured faces jump? ``discontinuity_pixels`` (``course.discontinuities``,
re-exported here) marks every pixel whose square a silhouette, a colour change, an intersection line or a
near/far cut touches; everything else is covered by faces of one colour, and one sample there is exact.
"""
from __future__ import annotations

import torch

from .camera import Camera
from .coverage import exact_coverage
from .discontinuities import _color_keys, discontinuity_pixels, segment_pixels
from .raster import Fragments, rasterize
from .tensors import as_tensor

__all__ = [
    "regular_offsets", "jittered_offsets", "sample_fragments", "resolve", "flat_colors",
    "supersample", "segment_pixels", "discontinuity_pixels", "adaptive_supersample", "exact_coverage",
]


# ----------------------------------------------------------------------------------- where the samples go

def regular_offsets(k: int, *, dtype=torch.float64, device=None) -> torch.Tensor:
    """(k², 2) the centres of a k × k grid in the unit pixel square, row by row: ``((a + ½)/k, (b + ½)/k)``
    for column a and row b; sample ``s = b k + a``. The same offsets serve every pixel."""
    k = _check_k(k)
    a = torch.arange(k, dtype=dtype, device=device)
    grid = torch.stack(torch.meshgrid(a, a, indexing="xy"), -1).reshape(-1, 2)   # (k², 2) as (a, b)
    return (grid + 0.5) / k


def _hash32(x: torch.Tensor) -> torch.Tensor:
    """A 32-bit integer hash (int64 tensors holding values < 2³²): shifts, xors and a multiplier small
    enough that no product overflows int64, so every device computes the same bits."""
    mask = 0xFFFFFFFF
    x = ((x >> 16) ^ x) * 0x45D9F3B & mask
    x = ((x >> 16) ^ x) * 0x45D9F3B & mask
    return (x >> 16) ^ x


def jittered_offsets(k: int, pixels, seed: int = 0, *, dtype=torch.float64) -> torch.Tensor:
    """(P, k², 2) stratified jitter: sample (a, b) of a pixel lies uniformly at random in the cell
    ``[a/k, (a+1)/k) × [b/k, (b+1)/k)``.

    pixels: (P,) flat pixel indices. The random numbers are a hash of (seed, pixel, sample), not draws from
    a generator, so a pixel's samples are the same whichever other pixels are sampled with it (the adaptive
    sampler asks for a few pixels, the full one for all, and both get identical samples).
    """
    k = _check_k(k)
    pixels = torch.as_tensor(pixels).long().reshape(-1)
    s = torch.arange(k * k, device=pixels.device)
    h = _hash32((_hash32(torch.full_like(pixels, int(seed) & 0xFFFFFFFF)) ^ pixels)[:, None])   # (P, 1)
    u = _hash32(h ^ (2 * s)) >> 8                                           # (P, k²) 24 random bits each
    v = _hash32(h ^ (2 * s + 1)) >> 8
    jitter = torch.stack([u, v], -1).to(dtype) / 2.0**24                    # in [0, 1), exact in float32 too
    return (regular_offsets(k, dtype=dtype, device=pixels.device) - 0.5 / k + jitter / k)


def _check_k(k) -> int:
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ValueError(f"samples per axis k must be a positive int, got {k!r}")
    return k


def _pixel_list(pixels, camera) -> torch.Tensor:
    H, W = camera.height, camera.width
    if pixels is None:
        return torch.arange(H * W, device=camera.K.device)
    pixels = torch.as_tensor(pixels, device=camera.K.device)
    return pixels.reshape(-1).nonzero().squeeze(1) if pixels.dtype == torch.bool else pixels.long()


def sample_fragments(mesh, camera: Camera, k: int, *, jitter: bool = False, seed: int = 0, pixels=None,
                     cull_backfaces: bool = False) -> Fragments:
    """Rasterize k × k samples in each listed pixel: Fragments of shape (P, k²).

    pixels: None (all H*W pixels, row-major), an (H, W) bool mask, or (P,) flat indices. jitter: stratified
    jitter (``jittered_offsets``) instead of the regular grid.
    """
    pix = _pixel_list(pixels, camera)
    offsets = jittered_offsets(k, pix, seed) if jitter else regular_offsets(_check_k(k))
    return rasterize(mesh, camera, samples=offsets, pixels=pix, cull_backfaces=cull_backfaces)


def resolve(values: torch.Tensor) -> torch.Tensor:
    """The box filter: (P, S, C) sample values → (P, C) their mean.

    The samples are added one after another in sample order and the sum divided by S, so a pixel's result
    does not depend on how many other pixels are resolved with it (a vectorised ``mean`` may add in another
    order for another shape, and the last bit would differ between the adaptive and the full sampler).
    """
    if values.dim() != 3 or values.shape[1] == 0:
        raise ValueError(f"values must have shape (P, S, C) with S >= 1, got {tuple(values.shape)}")
    total = values[:, 0]
    for s in range(1, values.shape[1]):
        total = total + values[:, s]
    return total / values.shape[1]


# ---------------------------------------------------------------------------------- flat-coloured images

def _check_colors(face_colors, mesh, background):
    colors = as_tensor(face_colors, name="face_colors")
    if colors.dim() != 2 or colors.shape != (mesh.faces.shape[0], 3):
        raise ValueError(f"face_colors must have shape (F, 3) = ({mesh.faces.shape[0]}, 3), "
                         f"got {tuple(colors.shape)}")
    if not torch.isfinite(colors).all():
        raise ValueError("face_colors contains NaN or inf")
    bg = as_tensor(background, dtype=colors.dtype, device=colors.device, name="background")
    if bg.numel() != 3:
        raise ValueError(f"background must be an RGB triple, got shape {tuple(bg.shape)}")
    return colors, bg.reshape(3)


def flat_colors(face_id: torch.Tensor, face_colors: torch.Tensor, background) -> torch.Tensor:
    """The colour of every sample: face_id (...) → (..., 3), the face's colour or the background (-1)."""
    colors = face_colors[face_id.clamp_min(0)]
    return torch.where((face_id >= 0)[..., None], colors, background)


def supersample(mesh, camera: Camera, face_colors, k: int, *, jitter: bool = False, seed: int = 0,
                background=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """Flat-coloured faces, k × k samples per pixel, box-filtered: (H, W, 3).

    face_colors: (F, 3); background: (3,) where no face is hit. Compare with ``exact_coverage``, the same
    integral in closed form.
    """
    colors, bg = _check_colors(face_colors, mesh, background)
    frags = sample_fragments(mesh, camera, k, jitter=jitter, seed=seed)
    return resolve(flat_colors(frags.face_id, colors, bg)).view(camera.height, camera.width, 3)


def adaptive_supersample(mesh, camera: Camera, face_colors, k: int, *, jitter: bool = False, seed: int = 0,
                         background=(0.0, 0.0, 0.0)):
    """Flat-coloured faces, k × k samples only in the pixels a discontinuity touches: (H, W, 3) and the
    (H, W) bool mask of those pixels.

    On marked pixels the samples are exactly those of ``supersample`` (same positions, same rasterizer), so
    the face ids and the box-filter sums agree to the last bit. On the others every sample would see the
    same colour, so one sample (the pixel centre) decides, and its colour is resolved as k² equal samples,
    which again matches ``supersample`` bit for bit.
    """
    colors, bg = _check_colors(face_colors, mesh, background)
    H, W = camera.height, camera.width
    S = _check_k(k) ** 2
    marked = discontinuity_pixels(mesh, camera, _color_keys(colors))
    base = rasterize(mesh, camera)                                           # one sample per pixel
    color = flat_colors(base.face_id.reshape(-1), colors, bg)                # (H*W, 3)
    image = resolve(color[:, None, :].expand(-1, S, -1))                     # k² equal samples
    pix = marked.reshape(-1).nonzero().squeeze(1)
    if pix.numel():
        frags = sample_fragments(mesh, camera, k, jitter=jitter, seed=seed, pixels=pix)
        image = image.index_put((pix,), resolve(flat_colors(frags.face_id, colors, bg)))
    return image.view(H, W, 3), marked
