"""What a fit gets wrong, on held-out views (lectures 10 and 15): its error split by where it falls.

A fit's held-out PSNR is one number; ``error_anatomy`` says where its squared error lies, pixel by pixel against
the target's held-out images and hard silhouettes (``ShadedData.held_out_images``, ``held_out_masks``):

* **edge**: pixels within one pixel of the target's silhouette (the mask differs from a neighbour's: the
  outline, where a fit's coverage blurs or shifts);
* **inside**: pixels on the target, away from its outline, where the target shows its own inside (a face seen
  from behind: an open surface seen through its opening; on the teapot, the gap under the lid, which floats in
  the rim's opening), given as ``inside`` (``inside_masks``): a carved hull cannot hold such a gap, nor any
  fit that only deforms it;
* **floaters**: pixels off the target, away from its outline, where the fit is not the background (it differs
  from it by more than ``tolerance`` in some channel): matter where there is none;
* **see-through**: the other pixels on the target, away from its outline, where the fit shows the background (within
  ``tolerance`` of it): holes, or surfaces no training view saw;
* **shading**: the rest of the target's pixels, where the fit covers the surface with the wrong colour;
* **background**: the rest of the pixels off the target (the fit faint there, under ``tolerance``).

For each region: its pixel count over the views, its share of the total squared error, and (floaters and
see-through) how many of the views hold any. ``worst_view``: the view with the largest squared error.
"""
from __future__ import annotations

import torch

from . import losses

__all__ = ["REGIONS", "error_anatomy", "inside_masks"]

REGIONS = ("edge", "inside", "floaters", "see-through", "shading", "background")


def inside_masks(mesh, cameras) -> torch.Tensor:
    """(M, H, W) bool: the pixels (centres) where ``mesh`` shows a face from behind in each of ``cameras``
    (the face's normal, by its counter-clockwise order, points away from the viewer: an open surface's inside)."""
    from ..raster import rasterize
    verts = mesh.verts.detach().to(torch.float64)
    tri = verts[mesh.faces]
    normals = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1)
    out = []
    with torch.no_grad():
        for camera in cameras:
            face = rasterize(mesh, camera).face_id
            hit = face >= 0
            f = face[hit]
            if camera.orthographic:
                away = normals[f] @ camera.R.to(torch.float64)[2]
            else:
                away = (normals[f] * (tri[f, 0] - camera.eye.to(torch.float64))).sum(1)   # the plane's sign
            mask = torch.zeros_like(hit)
            mask[hit] = away > 0
            out.append(mask)
    return torch.stack(out)


def _outline(masks: torch.Tensor) -> torch.Tensor:
    """(M, H, W) bool: pixels whose mask differs from one of their 8 neighbours' (the image border repeats)."""
    m = masks.bool()
    padded = torch.nn.functional.pad(m[:, None].float(), (1, 1, 1, 1), mode="replicate")[:, 0].bool()
    H, W = m.shape[1:]
    out = torch.zeros_like(m)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            out |= padded[:, di:di + H, dj:dj + W] != m
    return out


def error_anatomy(renders, targets, masks, background, *, inside=None, tolerance: float = 0.1) -> dict:
    """Where the squared error of ``renders`` (M, H, W, 3) against ``targets`` (M, H, W, 3) lies (module
    docstring), ``masks`` (M, H, W) the target's hard silhouettes, ``background`` (3,) the colour off the target, ``inside``
    (M, H, W) bool where the target shows its inside (``inside_masks``; None: no such region).

    Returns {region: {"pixels": int, "share": float (of the total squared error), "views": int (views holding
    any)} for each of ``REGIONS``, "sse": the total squared error, "worst_view": int, "psnr": [per-view PSNR
    (dB)], "regions": {region: (M, H, W) bool}}; the regions split the pixels (shares sum to 1). The renders are
    clamped to [0, 1] first, as the held-out PSNR clamps them."""
    r = torch.as_tensor(renders, dtype=torch.float64)
    t = torch.as_tensor(targets, dtype=torch.float64)
    m = torch.as_tensor(masks).bool()
    if r.dim() != 4 or r.shape[-1] != 3 or r.shape != t.shape:
        raise ValueError(f"renders and targets must both have shape (M, H, W, 3), got {tuple(r.shape)} and "
                         f"{tuple(t.shape)}")
    if tuple(m.shape) != tuple(r.shape[:3]):
        raise ValueError(f"masks must have shape {tuple(r.shape[:3])} (one per view), got {tuple(m.shape)}")
    if not bool(torch.isfinite(r).all()):
        raise ValueError("renders hold NaN or inf")
    bg = torch.as_tensor(background, dtype=torch.float64)
    if tuple(bg.shape) != (3,):
        raise ValueError(f"background must have shape (3,), got {tuple(bg.shape)}")
    if inside is None:
        inside = torch.zeros_like(m)
    inside = torch.as_tensor(inside).bool()
    if inside.shape != m.shape:
        raise ValueError(f"inside must have the masks' shape {tuple(m.shape)}, got {tuple(inside.shape)}")
    if not tolerance > 0:
        raise ValueError(f"tolerance must be positive, got {tolerance!r}")
    r = r.clamp(0, 1)
    err = ((r - t) ** 2).sum(-1)                                                # (M, H, W)
    shows_bg = ((r - bg).abs().amax(-1) <= tolerance)
    edge = _outline(m)
    body = m & ~edge & ~inside
    regions = {"edge": edge, "inside": m & ~edge & inside, "floaters": ~m & ~edge & ~shows_bg,
               "see-through": body & shows_bg, "shading": body & ~shows_bg, "background": ~m & ~edge & shows_bg}
    total = float(err.sum())
    out = {}
    for name in REGIONS:
        sel = regions[name]
        out[name] = {"pixels": int(sel.sum()), "share": float(err[sel].sum()) / total if total > 0 else 0.0,
                     "views": int(sel.flatten(1).any(1).sum())}
    out["sse"] = total
    out["worst_view"] = int(err.flatten(1).sum(1).argmax())
    out["psnr"] = [float(losses.psnr(a, b)) for a, b in zip(r, t)]           # as the fits' held-out PSNR
    out["regions"] = regions
    return out
