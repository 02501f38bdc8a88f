"""Texture lookups (lectures 04 and 05): nearest and bilinear, and mipmaps.

A texture is an image (Ht, Wt, C), row 0 at the top, addressed by texture coordinates uv with u to the right
and v up (uv (0, 0) is the bottom-left corner). ``sample_texture`` looks up one level with a nearest or
bilinear filter. Where the texture is *minified* (many texels fall into one pixel: far away, at grazing
angles) one lookup per pixel aliases into moiré, and supersampling only pushes the problem further away.
Mipmaps (Williams 1983, "Pyramidal parametrics") prefilter instead: ``mip_pyramid`` halves the texture
again and again, ``uv_derivatives`` measures each fragment's footprint in the texture exactly, ``mip_level``
turns the footprint into a level λ, and ``sample_texture_mip`` blends bilinear lookups in the two levels
around λ (trilinear filtering).
"""
from __future__ import annotations

import torch

from course.tensors import _as_faces, _check_count, _check_finite, as_tensor

__all__ = ["sample_texture", "mip_level", "mip_pyramid", "uv_derivatives", "sample_texture_mip"]


def sample_texture(texture, uv, mode: str = "bilinear") -> torch.Tensor:
    """Look up a texture at texture coordinates.

    texture: (Ht, Wt, C) (or (Ht, Wt)), row 0 at the top. uv: (..., 2), u to the right and v up, so uv (0, 0)
    is the bottom-left corner of the image and texel (row r, col c) has its centre at
    ``u = (c + 0.5) / Wt, v = 1 - (r + 0.5) / Ht``. ``mode``: ``"bilinear"`` blends the 4 nearest texel
    centres; ``"nearest"`` takes the texel containing uv. Lookups beyond [0, 1] clamp to the edge texels.
    Returns (..., C) in the texture's dtype. Bilinear is differentiable w.r.t. the texture and uv (the uv
    gradient is 0 where the lookup clamps); nearest only w.r.t. the texture.
    """
    if mode not in ("bilinear", "nearest"):
        raise ValueError(f"texture filter must be 'bilinear' or 'nearest', got {mode!r}")
    tex = as_tensor(texture, name="texture")
    if tex.dim() == 2:
        tex = tex[..., None]
    if tex.dim() != 3 or tex.shape[0] == 0 or tex.shape[1] == 0 or tex.shape[2] == 0:
        raise ValueError(f"texture must have shape (Ht, Wt, C), none of them 0, got {tuple(tex.shape)}")
    _check_finite(tex, "texture")
    uv = as_tensor(uv, dtype=tex.dtype, device=tex.device, name="uv")
    if uv.shape[-1:] != (2,):
        raise ValueError(f"uv must have shape (..., 2), got {tuple(uv.shape)}")
    _check_finite(uv, "uv", allow_inf=True)                                 # ±inf clamps to the edge
    Ht, Wt, _ = tex.shape
    uv = torch.nan_to_num(uv, nan=0.0, posinf=2.0, neginf=-1.0)             # keep the index math finite
    x = uv[..., 0] * Wt - 0.5                                                # texel column; centres at integers
    y = (1 - uv[..., 1]) * Ht - 0.5                                          # texel row; row 0 at the top (v = 1)
    if mode == "nearest":
        col = (x.detach() + 0.5).floor().clamp(0, Wt - 1).long()           # the texel containing uv
        row = (y.detach() + 0.5).floor().clamp(0, Ht - 1).long()
        return tex[row, col]
    x, y = x.clamp(0, Wt - 1), y.clamp(0, Ht - 1)                           # clamp to edge
    c0, r0 = x.detach().floor().long(), y.detach().floor().long()
    c1, r1 = (c0 + 1).clamp(max=Wt - 1), (r0 + 1).clamp(max=Ht - 1)
    fx, fy = (x - c0)[..., None], (y - r0)[..., None]                        # (..., 1) blend weights
    top = tex[r0, c0] * (1 - fx) + tex[r0, c1] * fx
    bottom = tex[r1, c0] * (1 - fx) + tex[r1, c1] * fx
    return top * (1 - fy) + bottom * fy


# ------------------------------------------------------------------------------ mip levels (task 4.4)

def mip_level(duv_dx, duv_dy, texture_size) -> torch.Tensor:
    """The mip level λ (level of detail) a pixel samples a texture at, from its screen-space uv derivatives.

    duv_dx, duv_dy: (N, 2) the change of (u, v) per pixel step in x and in y (uv with v up, as in
    ``sample_texture``); texture_size: (Ht, Wt), level 0's size in texels. Returns (N,) float in duv_dx's
    dtype: λ = max(0, log2 ρ) with ρ = max(|(Wt ∂u/∂x, Ht ∂v/∂x)|, |(Wt ∂u/∂y, Ht ∂v/∂y)|), the length in
    texels of the longer side of the pixel's footprint (the OpenGL specification's scale factor, no bias).
    Level λ halves the texture λ times, so one of its texels covers about one pixel. λ = 0 where ρ <= 1
    (magnification: the full-size texture), and where the derivatives are zero.
    """
    dx = as_tensor(duv_dx, name="duv_dx")
    dy = as_tensor(duv_dy, dtype=dx.dtype, device=dx.device, name="duv_dy")
    if dx.shape != dy.shape or dx.shape[-1:] != (2,):
        raise ValueError(f"duv_dx and duv_dy must both have shape (N, 2), got {tuple(dx.shape)} and {tuple(dy.shape)}")
    _check_finite(dx, "duv_dx", allow_inf=True), _check_finite(dy, "duv_dy", allow_inf=True)
    if isinstance(texture_size, torch.Size):
        texture_size = tuple(texture_size)
    if not isinstance(texture_size, (tuple, list)) or len(texture_size) != 2:
        raise ValueError(f"texture_size must be (Ht, Wt), level 0's size in texels, got {texture_size!r}")
    height, width = (float(_check_count(s, "texture_size")) for s in texture_size)
    texels = torch.tensor([width, height], dtype=dx.dtype, device=dx.device)   # u counts columns, v rows
    rho = torch.maximum(torch.linalg.vector_norm(dx * texels, dim=-1),
                        torch.linalg.vector_norm(dy * texels, dim=-1))         # (N,) footprint in texels
    return torch.log2(rho.clamp_min(1.0))



# ------------------------------------------------------------------- mipmaps: trilinear texture lookup

def _halve(x: torch.Tensor, dim: int) -> torch.Tensor:
    """Shrink axis ``dim`` of ``x`` from n to ceil(n / 2) samples, each the area average of what it covers.

    Output sample j covers input texels [j s, (j + 1) s) with s = n / ceil(n / 2) (s = 2 when n is even, a
    little less when n is odd), so it takes up to three texels, weighted by how much of each it covers. For
    even n this is the plain average of texels 2j and 2j + 1; for any n the mean is kept exactly.
    """
    n = x.shape[dim]
    if n == 1:
        return x
    m = (n + 1) // 2
    step = n / m
    lo = torch.arange(m, dtype=torch.float64, device=x.device) * step      # (m,) each output's footprint
    hi = lo + step
    first = lo.floor().long()
    out = 0
    for k in range(3):                                                      # a footprint spans <= 3 texels
        i = first + k
        left = i.double()
        w = (torch.minimum(left + 1, hi) - torch.maximum(left, lo)).clamp_min(0) / step   # (m,) overlap
        shape = [1] * x.dim()
        shape[dim] = m
        out = out + x.index_select(dim, i.clamp(max=n - 1)) * w.to(x.dtype).view(shape)
    return out


def mip_pyramid(texture) -> list:
    """The mip pyramid of a texture: level 0 is ``texture`` itself, each next level half its size, down to 1×1.

    texture: (Ht, Wt, C) or (Ht, Wt). Returns a list of tensors (Ht_k, Wt_k, C) (or (Ht_k, Wt_k)) with
    ``Ht_{k+1} = ceil(Ht_k / 2)`` (likewise Wt; a side that reached 1 stays 1), ``1 + ceil(log2 max(Ht, Wt))``
    levels. Each texel of level k + 1 is the 2×2 box average of level k's texels beneath it. An odd side
    n is split into ceil(n/2) equal footprints of n / ceil(n/2) < 2 texels each, and a texel averages by area
    what its footprint covers (a weighted average of up to 3 texels per axis, no padding), so every level
    has exactly the texture's mean and the last level *is* the mean. Differentiable w.r.t. the texture.
    """
    tex = as_tensor(texture, name="texture")
    if tex.dim() not in (2, 3) or tex.shape[0] == 0 or tex.shape[1] == 0:
        raise ValueError(f"texture must have shape (Ht, Wt, C) or (Ht, Wt), got {tuple(tex.shape)}")
    _check_finite(tex, "texture")
    levels = [tex]
    while levels[-1].shape[0] > 1 or levels[-1].shape[1] > 1:
        levels.append(_halve(_halve(levels[-1], 0), 1))
    return levels


def uv_derivatives(uvs, faces, fragments, verts, camera):
    """Screen-space derivatives of the perspective-correct uv at every fragment: how far (u, v) moves when the
    image point moves one pixel right (``duv_dx``) or down (``duv_dy``). The footprint that picks a mip level.

    uvs: (V, 2) per-vertex texture coordinates; faces: (F, 3) int64; fragments: Fragments of any shape
    (``...``: (H, W) from ``rasterize``, or (P, S) samples), whose ``bary`` are the weights of the 3D hit point;
    verts: (V, 3) world positions; camera: the Camera that made the fragments. Returns ``duv_dx``, ``duv_dy``
    (..., 2) in the promoted dtype of verts and camera, zero where ``face_id < 0``.

    Computed exactly, per fragment and on its own (never from neighbouring pixels, which belong to other
    faces at silhouettes, and never from the array index, which is no pixel position for samples): the hit
    point ``P = Σ b_k v_k`` (camera space) lies on the ray of image point ``p = (x, y, 1)``,
    ``d = K⁻¹ p = P / (K₃ · P)`` for a pinhole camera. Moving p by one pixel moves ``d`` by ``K⁻¹ e_x``, and
    the hit point slides within the face's plane (normal n) along::

        ∂P/∂x = a - r (n · a) / (n · r),   a = (K₃ · P) K⁻¹ e_x, r = P     (perspective)
                                           a = (K⁻¹ e_x)_xy,    r = +z    (orthographic: uv is affine on screen)

    Writing ∂P/∂x = β₁ e₁ + β₂ e₂ on the face's edges gives the barycentrics' derivatives, and
    ``∂uv/∂x = β₁ (uv₁ - uv₀) + β₂ (uv₂ - uv₀)``. This is the quotient rule of the hint
    ``uv = Σ λ_k q_k uv_k / Σ λ_k q_k`` (λ_k screen barycentrics, q_k = 1/z_k) written in 3D. Needs no
    gradient: it only picks a level, so it runs under ``torch.no_grad()`` and returns detached tensors.
    Faces seen edge-on give huge (finite) derivatives, i.e. the coarsest level.
    """
    from course.raster import _is_camera
    if not _is_camera(camera):
        raise TypeError(f"camera must be a course.camera.Camera, got {type(camera).__name__}")
    if not (hasattr(fragments, "face_id") and hasattr(fragments, "bary")):
        raise TypeError(f"fragments must be Fragments (from rasterize or raycast), got {type(fragments).__name__}")
    with torch.no_grad():
        verts = as_tensor(verts, name="verts").detach()
        dtype = torch.promote_types(verts.dtype, camera.dtype)
        verts = verts.to(dtype)
        uvs = as_tensor(uvs, dtype=dtype, device=verts.device, name="uvs").detach()
        if verts.dim() != 2 or verts.shape[1] != 3:
            raise ValueError(f"verts must have shape (V, 3), got {tuple(verts.shape)}")
        if uvs.shape != (verts.shape[0], 2):
            raise ValueError(f"uvs must have shape (V, 2) = ({verts.shape[0]}, 2), got {tuple(uvs.shape)}")
        _check_finite(verts, "verts"), _check_finite(uvs, "uvs")
        faces = _as_faces(faces, "faces", num_verts=verts.shape[0], device=verts.device)
        face_id = fragments.face_id
        if fragments.bary.shape != (*face_id.shape, 3):
            raise ValueError(f"fragments.bary must have shape {(*face_id.shape, 3)}, got "
                             f"{tuple(fragments.bary.shape)}")
        if face_id.numel() and int(face_id.max()) >= faces.shape[0]:
            raise ValueError(f"fragments reference face {int(face_id.max())} but faces has {faces.shape[0]} rows")
        hit = face_id >= 0
        tri = faces[face_id[hit]]                                           # (M, 3) vertex ids
        b = fragments.bary.detach().to(dtype)[hit]                          # (M, 3)
        K, R, t = (x.detach().to(dtype) for x in (camera.K, camera.R, camera.t))
        v = verts[tri]                                                      # (M, 3, 3) world
        v0 = v[:, 0] @ R.T + t                                              # (M, 3) camera space
        e1, e2 = (v[:, 1] - v[:, 0]) @ R.T, (v[:, 2] - v[:, 0]) @ R.T      # edges, rotated only
        n = torch.linalg.cross(e1, e2)                                      # (M, 3) face normal (unnormalised)
        P = v0 + b[:, 1:2] * e1 + b[:, 2:3] * e2                            # (M, 3) hit point
        K_inv = torch.linalg.inv(K)
        tiny = torch.finfo(dtype).tiny ** 0.5

        def safe(den):                                                      # keeps edge-on faces finite
            return torch.where(den.abs() < tiny, torch.full_like(den, tiny), den)

        if camera.orthographic:
            r = torch.zeros_like(P)
            r[:, 2] = 1
            scale = torch.ones_like(P[:, :1])
        else:
            r = P
            scale = (P @ K[2])[:, None]                                     # (M, 1): P = scale · K⁻¹ p
        n_r = safe((n * r).sum(-1, keepdim=True))
        n_n = safe((n * n).sum(-1, keepdim=True))
        uv = uvs[tri]                                                       # (M, 3, 2)
        out = []
        for axis in (0, 1):                                                 # x, then y
            step = K_inv[:, axis].expand_as(P).clone()                      # (M, 3) ray change per pixel
            if camera.orthographic:
                step[:, 2] = 0
            a = scale * step
            dP = a - r * (n * a).sum(-1, keepdim=True) / n_r                # (M, 3) within the face's plane
            beta1 = (torch.linalg.cross(dP, e2) * n).sum(-1, keepdim=True) / n_n
            beta2 = (torch.linalg.cross(e1, dP) * n).sum(-1, keepdim=True) / n_n
            duv = beta1 * (uv[:, 1] - uv[:, 0]) + beta2 * (uv[:, 2] - uv[:, 0])   # (M, 2)
            full = torch.zeros(*face_id.shape, 2, dtype=dtype, device=verts.device)
            full[hit] = duv
            out.append(full)
    return out[0], out[1]


def sample_texture_mip(texture, uv, duv_dx, duv_dy) -> torch.Tensor:
    """Trilinear texture lookup: bilinear in the two mip levels around the pixel's level of detail, blended.

    texture: a pyramid from :func:`mip_pyramid` (a list of levels (Ht_k, Wt_k, C)), or one texture
    (Ht, Wt, C) / (Ht, Wt) whose pyramid is built here (build it once yourself when you look up many times).
    uv: (..., 2) as in :func:`sample_texture`; duv_dx, duv_dy: (..., 2) its screen-space derivatives (from
    :func:`uv_derivatives`). The level is λ = :func:`mip_level` (level 0's size), clamped to the last level;
    the result is ``(1 - f) bilinear(level ⌊λ⌋) + f bilinear(level ⌊λ⌋ + 1)``, f = λ - ⌊λ⌋. Where the
    footprint is at most one texel (λ = 0) this is exactly ``sample_texture(texture, uv, "bilinear")``; where
    it covers the whole texture, the texture's mean. Returns (..., C). Differentiable w.r.t. the texture
    and uv; not w.r.t. the level (the derivatives are detached).
    """
    levels = list(texture) if isinstance(texture, (list, tuple)) else mip_pyramid(texture)
    if not levels:
        raise ValueError("the mip pyramid is empty; build one with mip_pyramid(texture)")
    levels = [as_tensor(level, name="mip level") for level in levels]
    levels = [level[..., None] if level.dim() == 2 else level for level in levels]
    tex0 = levels[0]
    for k, level in enumerate(levels):
        if level.dim() != 3 or level.shape[0] == 0 or level.shape[1] == 0 or level.shape[2] != tex0.shape[2]:
            raise ValueError(f"mip level {k} must have shape (Ht, Wt, {tex0.shape[2]}), got {tuple(level.shape)}")
    uv = as_tensor(uv, dtype=tex0.dtype, device=tex0.device, name="uv")
    if uv.shape[-1:] != (2,):
        raise ValueError(f"uv must have shape (..., 2), got {tuple(uv.shape)}")
    _check_finite(uv, "uv", allow_inf=True)
    dx = as_tensor(duv_dx, dtype=tex0.dtype, device=tex0.device, name="duv_dx").detach()
    dy = as_tensor(duv_dy, dtype=tex0.dtype, device=tex0.device, name="duv_dy").detach()
    if dx.shape != uv.shape or dy.shape != uv.shape:
        raise ValueError(f"duv_dx and duv_dy must have uv's shape {tuple(uv.shape)}, got "
                         f"{tuple(dx.shape)} and {tuple(dy.shape)}")
    last = len(levels) - 1
    lam = torch.nan_to_num(mip_level(dx, dy, tex0.shape[:2]), nan=0.0).clamp(0, last).reshape(-1)   # (N,)
    lo = lam.floor()
    f = lam - lo
    lo = lo.long()
    hi = (lo + 1).clamp(max=last)
    uv_flat = uv.reshape(-1, 2)
    out = torch.zeros(uv_flat.shape[0], tex0.shape[2], dtype=tex0.dtype, device=tex0.device)
    for k, level in enumerate(levels):                                      # each level: only its texels
        w = torch.where(lo == k, 1 - f, 0.0) + torch.where(hi == k, f, 0.0)  # (N,) weight of level k
        idx = (w > 0).nonzero().squeeze(1)
        if idx.numel():
            out = out.index_add(0, idx, sample_texture(level, uv_flat[idx]) * w[idx, None])
    return out.reshape(*uv.shape[:-1], tex0.shape[2])
