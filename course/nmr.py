"""The Neural 3D Mesh Renderer's approximate gradient (lecture 08), beside soft rasterization (``course.soft``).

A rasterized pixel is a step function of every vertex position: as a vertex moves, the pixel's colour
jumps when an edge crosses the pixel centre and is constant in between, so its derivative is zero almost
everywhere. Soft rasterization (``course.soft``) blurs the image until it has a derivative; the Neural 3D
Mesh Renderer keeps the image and invents one.

**The Neural 3D Mesh Renderer** (Kato, Ushiku and Harada, "Neural 3D Mesh Renderer", CVPR 2018),
``nmr_rasterize`` and ``nmr_image``. The forward pass is the hard rasterizer, unchanged. The backward pass
replaces the step by a secant: for pixel P and the screen coordinate x of a vertex, find the displacement
δx of the vertex at which an edge of its face would cross P's centre, and the colour change δI the pixel
would see there; use ``∂I/∂x ≈ δI / δx``. The paper's sign rule keeps only useful secants: with δᴾ = ∂L/∂I
the incoming gradient, the term is dropped where ``δᴾ · δI ≥ 0`` (moving the vertex that way would not
lower the loss). A pixel outside the face can be covered by moving an edge toward it (the paper's fig. 2);
a pixel inside can be uncovered by moving either of the two edges that bound its row, and both terms are
summed (fig. 3). Rows give the gradient of x, columns that of y. Because of the sign rule the backward is
*not linear* in the incoming gradient: ``backward(2 g) = 2 backward(g)`` holds, ``backward(g + h)`` does
not equal ``backward(g) + backward(h)``. Two choices of ours, both options: δx is floored at
``min_step`` pixels (0.5 by default: the secant has a pole where an edge already passes through the centre),
and only pixels within ``reach`` pixels of an edge along the row or column are visited (None: the whole
row, as in the paper). With reach None that is every pixel of every row a face spans, hundreds of millions of
(pixel, edge) terms on a big mesh: the pixels near a face's span are visited one by one, CHUNK at a time
(``_nmr_pixels``), and those farther than ``min_step`` beyond it, where only covering is possible and the
floor never applies, as one table per image row, (faces crossing the row) × (its pixels), whose sums
need no per-pixel bookkeeping (``_nmr_row_tables``).

It gives a gradient with respect to ``mesh.verts``, the colours, and the camera's K, R, t.
"""
from __future__ import annotations

import math

import torch

from .camera import world_to_camera
from .raster import _camera_space, _check_inputs, _project, rasterize
from .scan import _expand, _max3, _min3
from .soft import _background, _groups, _project_safe
from .tensors import _as_index, _check_finite, _check_flag, _check_real, as_tensor

__all__ = ["nmr_rasterize", "nmr_image", "NMRGradient"]

CHUNK = 1 << 18      # (pixel, edge) terms computed at once: bounds the memory of the backward (the tests set it
                     # small to force many chunks)
ROW_TABLES = 0.25    # the backward visits the pixels beyond min_step as per-row tables when reach is longer
                     # than this fraction of a row (reach None: always), else pixel by pixel


class NMRGradient(torch.autograd.Function):
    """Identity on the image in forward; in backward, the Neural 3D Mesh Renderer's approximate gradient of
    the image w.r.t. the screen positions of the vertices (Kato et al. 2018), and ∂L/∂I passed through to
    the image itself (so colours get their usual gradient). Use through ``nmr_image``."""

    @staticmethod
    def forward(ctx, verts_screen, image, scene):
        ctx.scene = scene                                                   # a dict of detached tensors
        ctx.save_for_backward(verts_screen, image)
        return image.clone()

    @staticmethod
    def backward(ctx, d_image):
        verts_screen, image = ctx.saved_tensors
        d_screen = _nmr_backward(verts_screen.detach(), image.detach(), d_image, **ctx.scene)
        return d_screen.to(verts_screen.dtype), d_image, None


def _check_nmr_options(cull_backfaces, reach, min_step):
    """cull_backfaces as a bool, reach as a float (None: inf) and min_step as a float, or a ValueError
    naming the argument (a string, a bool, NaN, a negative number)."""
    cull_backfaces = _check_flag(cull_backfaces, "cull_backfaces")
    reach = math.inf if reach is None else _check_real(reach, "reach (pixels, or None)", low=0, allow_inf=True)
    min_step = _check_real(min_step, "min_step", low=0, low_open=True)
    return cull_backfaces, reach, min_step


def nmr_image(image, mesh, camera, face_id, *, face_values=None, background=0.0, cull_backfaces: bool = True,
              reach: float | None = None, min_step: float = 0.5) -> torch.Tensor:
    """Attach NMR's approximate visibility gradient to an image rendered from hard fragments.

    image: (H, W, C) any shading of the fragments, finite (its own gradient, e.g. to colours or through the
    barycentrics, is kept); face_id: (H, W) integer face ids from the same ``rasterize`` call (-1:
    background). face_values: optional (F, C), the colour a face would give a pixel it newly covers (flat
    shading); without it, the colour of the face's nearest pixel along the row or column is used (the
    paper's code does the same), and the pixel is skipped where that pixel does not show the face.
    background: (C,) or a number, the colour beyond the image border. reach: how many pixels beyond an edge,
    along a row or column, a pixel can be and still receive a gradient from it (None: the whole image).
    min_step: the floor on |δx| in pixels. Faces crossing the near plane contribute no visibility gradient
    (their projected vertices are meaningless), nor do faces entirely beyond the far plane; a mesh without
    faces gets a zero gradient. Returns the image's values, with a backward that follows Kato et al.'s
    rule to ``mesh.verts`` and, through the projection, to the camera's K, R and t.
    """
    verts, faces = _check_inputs(mesh, camera)
    cull_backfaces, reach, min_step = _check_nmr_options(cull_backfaces, reach, min_step)
    H, W = camera.height, camera.width
    image = as_tensor(image, device=verts.device, name="image")
    if image.dim() != 3 or tuple(image.shape[:2]) != (H, W) or image.shape[2] < 1:
        raise ValueError(f"image must have shape (H, W, C) = ({H}, {W}, C) with C >= 1, got {tuple(image.shape)}")
    _check_finite(image, "image")
    C = image.shape[2]
    face_id = _as_index(face_id, "face_id", device=verts.device)            # integers only: never rounded
    if tuple(face_id.shape) != (H, W):
        raise ValueError(f"face_id must have shape (H, W) = ({H}, {W}), got {tuple(face_id.shape)}")
    if face_id.numel() and not (-1 <= int(face_id.min()) and int(face_id.max()) < faces.shape[0]):
        raise ValueError(f"face_id must hold -1 (background) or a face index below {faces.shape[0]}, got values "
                         f"from {int(face_id.min())} to {int(face_id.max())}")
    if face_values is not None:
        face_values = as_tensor(face_values, device=verts.device, name="face_values").double()
        if tuple(face_values.shape) != (faces.shape[0], C):
            raise ValueError(f"face_values must have shape ({faces.shape[0]}, {C}) (faces, image channels), "
                             f"got {tuple(face_values.shape)}")
        _check_finite(face_values, "face_values")
    bg = _background(background, C, torch.float64, verts.device)
    with torch.no_grad():
        v = _camera_space(verts, camera)                                    # (V, 3) float64
        z = v[faces][..., 2]
        keep = (_min3(z) >= camera.near) & (_min3(z) <= camera.far)
        if cull_backfaces:
            fv = v[faces]
            normal = torch.linalg.cross(fv[:, 1] - fv[:, 0], fv[:, 2] - fv[:, 0])
            keep &= (normal[:, 2] < 0) if camera.orthographic else ((normal * fv[:, 0]).sum(-1) < 0)
        fids = keep.nonzero().squeeze(1)
        nearness = -v[:, 2] if camera.orthographic else 1 / v[:, 2]        # affine on screen, larger = nearer
        depth_q = torch.full((H * W,), -math.inf, dtype=torch.float64, device=verts.device)
        hit = (face_id.reshape(-1) >= 0).nonzero().squeeze(1)
        xy, _ = _project(v, camera, camera.K.detach().double())             # (V, 2)
        tri = faces[face_id.reshape(-1)[hit]]                               # (M, 3) the visible faces
        q_r, dq = _row_plane(xy[tri, 0], xy[tri, 1], nearness[tri], (hit // W).double() + 0.5)
        depth_q[hit] = q_r + dq * ((hit % W).double() + 0.5)               # their q at the pixel centres
    scene = dict(faces=faces[fids], fids=fids, q=nearness, face_id=face_id.reshape(-1), depth_q=depth_q,
                 face_values=face_values, bg=bg, H=H, W=W, ortho=camera.orthographic, reach=reach,
                 min_step=min_step)
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    verts_cam = world_to_camera(verts.to(dtype), camera.R.to(dtype), camera.t.to(dtype))
    verts_screen, _ = _project_safe(verts_cam, camera, camera.K.to(dtype))  # (V, 2) differentiable
    return NMRGradient.apply(verts_screen, image, scene)


def nmr_rasterize(mesh, camera, *, face_colors=None, background=0.0, cull_backfaces: bool = True,
                  reach: float | None = None, min_step: float = 0.5) -> torch.Tensor:
    """The hard rasterizer's image with NMR's approximate gradient (Kato et al. 2018).

    face_colors: None for a silhouette, returned as (H, W) (1 where a face is visible); or (F, C) flat
    face colours (finite; integers are taken as floats), returned as (H, W, C) in the mesh's dtype promoted
    with theirs, background (C,) or a number elsewhere. reach, min_step: see ``nmr_image``. A mesh without
    faces gives the background and a zero gradient. Gradients flow to ``mesh.verts``, to ``face_colors``
    and to the camera's K, R and t.
    """
    verts, faces = _check_inputs(mesh, camera)
    cull_backfaces, reach, min_step = _check_nmr_options(cull_backfaces, reach, min_step)
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    if face_colors is None:
        values = torch.ones(faces.shape[0], 1, dtype=dtype, device=verts.device)
    else:
        values = as_tensor(face_colors, device=verts.device, name="face_colors")
        if values.dim() != 2 or values.shape[0] != faces.shape[0] or values.shape[1] < 1:
            raise ValueError(f"face_colors must have shape ({faces.shape[0]}, C) with C >= 1 channels, got "
                             f"{tuple(values.shape)}")
        _check_finite(values, "face_colors")
        values = values.to(torch.promote_types(dtype, values.dtype))
    bg = _background(background, values.shape[1], values.dtype, verts.device)
    frags = rasterize(mesh, camera, cull_backfaces=cull_backfaces)
    if face_colors is None:
        image = frags.mask.to(dtype)[..., None]                             # (H, W, 1)
    elif faces.shape[0] == 0:                                               # nothing to look up: the background
        image = bg.expand(camera.height, camera.width, -1).clone()
    else:
        image = torch.where(frags.mask[..., None], values[frags.face_id.clamp(min=0)], bg)
    out = nmr_image(image, mesh, camera, frags.face_id, face_values=values.detach(), background=bg.detach(),
                    cull_backfaces=cull_backfaces, reach=reach, min_step=min_step)
    return out[..., 0] if face_colors is None else out


def _nmr_backward(verts_screen, image, d_image, *, faces, fids, q, face_id, depth_q, face_values, bg, H, W,
                  ortho, reach, min_step):
    """∂L/∂(screen positions) (V, 2) by NMR's rule: rows give x, columns give y (the same code, transposed)."""
    dt = torch.promote_types(verts_screen.dtype, image.dtype)              # the working dtype
    d = torch.zeros(verts_screen.shape[0], 2, dtype=dt, device=verts_screen.device)
    if faces.shape[0] == 0:
        return d
    u, v, q, bg = verts_screen[:, 0].to(dt), verts_screen[:, 1].to(dt), q.to(dt), bg.to(dt)
    face_values = None if face_values is None else face_values.to(dt)
    img, g = image.detach().to(dt).reshape(H, W, -1), d_image.to(dt).reshape(H, W, -1)
    maps = dict(face_id=face_id.view(H, W), depth_q=depth_q.to(dt).view(H, W), image=img, g=g)
    shown = torch.zeros(int(max(fids.max(), face_id.max())) + 1, dtype=torch.bool, device=d.device)
    shown[face_id[face_id >= 0]] = True                                     # (faces) some pixel shows it
    for axis, (a, b, m) in enumerate(((u, v, maps), (v, u, {k: t.transpose(0, 1) for k, t in maps.items()}))):
        m = {k: t.reshape(t.shape[0] * t.shape[1], *t.shape[2:]) for k, t in m.items()}
        n_rows, n_cols = (H, W) if axis == 0 else (W, H)
        d[:, axis] = _nmr_scan(a, b, q, faces, fids, shown, m, face_values, bg, n_rows, n_cols, ortho, reach,
                               min_step)
    return d


def _nmr_scan(u, v, q, faces, fids, shown, m, face_values, bg, n_rows, n_cols, ortho, reach, min_step):
    """∂L/∂u (V,) for the coordinate u along rows of constant v (the centrepiece of NMR's backward).

    For every face and every row whose centre v_c it spans, the two edges crossing the row at u_l <= u_r;
    for each, the pixels from the crossing outward (up to ``reach``) and across the span inward. A pixel at
    u_p needs the edge (a, b) to move by δ = u_p - u_e, i.e. vertex a by δ / s_a (s_a its weight on the edge
    at this row), floored at ``min_step``; its colour would change by δI (covered: the face's colour, if the
    face is nearer than what is there; uncovered: the colour across the edge, if the face is the visible
    one). The term ∂L/∂I · δI / δx is kept only where ∂L/∂I · δI < 0.

    This function lists the entries, one per (face, row, side), with what each pixel's term needs; the
    pixels are visited by ``_nmr_pixels`` and, far beyond the span, by ``_nmr_row_tables``.
    """
    tu, tv, tq = u[faces], v[faces], q[faces]                               # (T, 3)
    first = torch.ceil(_min3(tv) - 0.5).clamp(min=0)                        # rows with centre in [v_min, v_max)
    last = (torch.ceil(_max3(tv) - 0.5) - 1).clamp(max=n_rows - 1)
    tri_of_seg, start = _expand((last - first + 1).clamp(min=0).long())
    row = first[tri_of_seg] + torch.arange(tri_of_seg.numel(), device=u.device) - start[tri_of_seg]
    vc = (row + 0.5)[:, None]                                               # (S, 1)
    va, vb = tv[tri_of_seg], tv[tri_of_seg].roll(-1, 1)                     # (S, 3) edges a→b
    ua, ub = tu[tri_of_seg], tu[tri_of_seg].roll(-1, 1)
    valid = (torch.minimum(va, vb) <= vc) & (vc < torch.maximum(va, vb))    # the edge crosses the row
    s_a = torch.where(valid, (vc - vb) / torch.where(valid, va - vb, 1.0), 0.0)   # a's weight at the crossing
    ue = ub + s_a * (ua - ub)                                               # (S, 3) crossings
    left = torch.where(valid, ue, math.inf).argmin(1, keepdim=True)         # (S, 1) edge index
    right = torch.where(valid, ue, -math.inf).argmax(1, keepdim=True)
    ok = (valid.sum(1) == 2).nonzero().squeeze(1)                           # a row meets exactly two edges
    # one entry per (segment, side): side 0 the left edge (inside is +u), 1 the right edge (inside is -u);
    # entries [0, n) are the left edges of the rows ok lists, entries [n, 2n) their right edges
    seg = torch.cat([ok, ok])
    edge = torch.cat([left[ok, 0], right[ok, 0]])
    side = torch.cat([torch.zeros_like(ok), torch.ones_like(ok)]).to(u.dtype)
    ul, ur = ue.gather(1, left)[seg, 0], ue.gather(1, right)[seg, 0]        # the span of the row
    u_e, s_e = ue[seg, edge], s_a[seg, edge]                                # this side's crossing, weight
    t, r = tri_of_seg[seg], row[seg]
    f, vid_a, vid_b = fids[t], faces[t, edge], faces[t, (edge + 1) % 3]
    base = r.long() * n_cols                                                # flat index of the row's start
    img, face_id = m["image"], m["face_id"]
    # uncovering (inside): the colour across the edge, the background beyond the border
    across = torch.where(side == 0, torch.ceil(u_e - 0.5) - 1, torch.floor(u_e - 0.5) + 1)
    a_ok = (across >= 0) & (across < n_cols)
    behind = torch.where(a_ok[:, None], img[base + across.clamp(0, n_cols - 1).long()], bg)   # (2S', C)
    # covering (outside): the face's colour (or that of its nearest pixel in the row, if it shows the face)
    if face_values is not None:
        colour, c_ok = face_values[f], torch.ones_like(a_ok)
    else:
        c_pix = base + torch.where(side == 0, torch.ceil(u_e - 0.5), torch.floor(u_e - 0.5)).clamp(
            0, n_cols - 1).long()
        colour, c_ok = img[c_pix], face_id[c_pix] == f
    # the face's q along the row, q(u) = q_r + dq u: nearer than what a pixel shows if q(u_p) > depth_q
    # (q: 1/z, or -z for an orthographic camera: larger is nearer; -inf on the background)
    q_r, dq = _row_plane(tu[t], tv[t], tq[t], r + 0.5)
    # Which pixels each entry visits: up to reach beyond its edge, and the span. When reach is long (the
    # paper's whole row), those farther than min_step beyond the span go to the row tables, and this pass
    # stops at `band` = min_step: its ranges reach a little farther (more than rounding), and the exact test
    # |u_p - u_e| <= band in _nmr_pixels (the tables use its complement) splits the pixels between the two.
    tables = reach > min_step and reach > ROW_TABLES * n_cols
    band, margin = (min_step, 0.25) if tables else (reach, 0.0)
    # (a face no pixel shows, hidden or a back face, uncovers nothing: its entries skip the span)
    span = shown[f]
    lo = torch.where(side == 0, torch.ceil(ul - band - margin - 0.5),
                     torch.where(span, torch.ceil(ul - 0.5), torch.floor(ur - 0.5) + 1)).clamp(min=0)
    hi = torch.where(side == 1, torch.floor(ur + band + margin - 0.5),
                     torch.where(span, torch.floor(ur - 0.5), torch.ceil(ul - 0.5) - 1)).clamp(max=n_cols - 1)
    entries = dict(lo=lo, hi=hi, ul=ul, ur=ur, u_e=u_e, s_e=s_e, side=side, base=base, behind=behind,
                   colour=colour, c_ok=c_ok, f=f, q_r=q_r, dq=dq, vid_a=vid_a, vid_b=vid_b)
    out = torch.zeros_like(u)
    for a, b in _groups((hi - lo + 1).clamp(min=0).long(), CHUNK):          # about CHUNK pixels at a time
        _nmr_pixels({k: x[a:b] for k, x in entries.items()}, m, out, ortho, min_step, band if tables else None)
    if tables:
        _nmr_row_tables(entries, r, m, out, face_values is None, ortho, band, reach, n_rows, n_cols)
    return out


def _nmr_pixels(e, m, out, ortho, min_step, band):
    """Add to ``out`` (V,) the terms of the pixels the entries ``e`` (a dict of per-entry tensors, a chunk
    of ``_nmr_scan``'s) visit, one element per (entry, pixel). band: None, or the distance beyond the span
    past which the row tables take the pixels over."""
    img, g, face_id, depth_q = m["image"], m["g"], m["face_id"], m["depth_q"]
    elem, e_start = _expand((e["hi"] - e["lo"] + 1).clamp(min=0).long())   # one element per (entry, pixel)
    take = lambda a: a.index_select(0, elem)                                # noqa: E731  per-entry → per-element
    col = take(e["lo"]) + torch.arange(elem.numel(), device=elem.device) - take(e_start)
    up = col + 0.5                                                          # (E,) the pixel centre's u
    pix = take(e["base"]) + col.long()
    inside = (up >= take(e["ul"])) & (up <= take(e["ur"]))
    here = img.index_select(0, pix)                                         # (E, C)
    q_p = take(e["q_r"]) + take(e["dq"]) * up
    nearer = (q_p > depth_q.index_select(0, pix)) & (ortho or (q_p > 0))    # q_p <= 0: the plane is behind us
    dI = torch.where(inside[:, None], take(e["behind"]), take(e["colour"])) - here   # (E, C)
    use = torch.where(inside, face_id.index_select(0, pix) == take(e["f"]), nearer & take(e["c_ok"]))
    dist = (up - take(e["u_e"])).abs()
    if band is not None:                                                    # farther out: the row tables'
        use &= inside | (dist <= band)
    dot = (g.index_select(0, pix) * dI).sum(1) * use                        # δᴾ · δI
    dot = torch.where(dot < 0, dot, 0.0)                                    # the sign rule
    sd = take(e["side"])
    direction = torch.where(inside, 1.0 - 2.0 * sd, 2.0 * sd - 1.0)         # which way the vertex moves
    for w, vid in ((e["s_e"], e["vid_a"]), (1 - e["s_e"], e["vid_b"])):
        # δx = δ / w, floored at min_step: ∂L/∂x = dot / δx = dot · w / (direction · max(|δ|, min_step · w))
        w = take(w)
        den = torch.maximum(dist, min_step * w).clamp(min=torch.finfo(dist.dtype).tiny)
        out.index_add_(0, take(vid), dot * w * direction / den)


def _nmr_row_tables(e, row, m, out, per_side, ortho, band, reach, n_rows, n_cols):
    """Add to ``out`` (V,) the covering terms of the pixels farther than ``band`` (>= min_step) beyond each
    face's span along its rows, and at most ``reach``: what makes the paper's whole-row reach expensive.

    There the floor on δx never applies (|δ| > min_step >= min_step · w), so a pixel's term is
    ``direction · w · min(0, δᴾ · δI) / |δ|`` and a row's terms sum to ``w`` times one sum per edge: the
    pixels left of the span feed its left edge, those right of it its right edge. For one image row the
    faces crossing it and the row's pixels form a table (faces × pixels) of dense arithmetic, no per-pixel
    indexing: δᴾ · δI = g · colour - g · here is one matrix product, the plane's q one outer product. Only
    the pixels where the sign rule can keep a term for some face are columns of the table (for a
    silhouette, the background where ∂L/∂I < 0). e: the entries of ``_nmr_scan``, the first half the
    left edges and the second half the right edges of the same rows (``row``: each entry's row);
    per_side: the covering colour differs between the two sides (no face_values)."""
    n = e["ul"].numel() // 2
    if n == 0:
        return
    img, g = m["image"], m["g"]
    C = img.shape[1]

    def coefficients(colour, c_ok):                                         # (n, C + 1): [colour, -1], or 0
        coef = torch.cat([colour, -torch.ones_like(colour[:, :1])], 1)       # where the colour is unknown
        return torch.where(c_ok[:, None], coef, 0.0)
    coef_l = coefficients(e["colour"][:n], e["c_ok"][:n])
    coef_r = coefficients(e["colour"][n:], e["c_ok"][n:]) if per_side else None
    # the pixels where some face's δᴾ · δI can be < 0: g · c - g · here >= Σ_c min(g_c lo_c, g_c hi_c) - g · here
    # over the colours' range [lo, hi] per channel; elsewhere (g = 0, or a silhouette's covered pixels) no term
    known = torch.cat([coef_l, coef_r]) if per_side else coef_l
    known = known[known[:, -1] != 0, :C]                                    # the colours in use
    if known.shape[0] == 0:
        return
    gi = (g * img).sum(1)                                                   # (P,) g · here
    bound = torch.minimum(g * known.amin(0), g * known.amax(0)).sum(1) - gi
    wanted = (bound < 0).view(n_rows, n_cols)
    rhs_all = torch.cat([g, gi[:, None]], 1).view(n_rows, n_cols, C + 1)    # [g, g · here] per pixel
    depth = m["depth_q"].view(n_rows, n_cols)
    if not ortho:
        depth = depth.clamp(min=0)                                          # q_p > depth and q_p > 0 at once
    empty = depth == (-math.inf if ortho else 0.0)                          # the background's pixels
    # A face behind the surface at every covered pixel of its row (a back face of a closed mesh, with
    # cull_backfaces=False) can only cover background: its table needs the background's columns alone.
    # Its q along the row is affine, so at most max(q(0), q(n_cols)); compared with the least q shown.
    row = row[:n].long()
    least = torch.where(wanted & ~empty, depth, math.inf).amin(1)           # (n_rows,)
    q_r, dq = e["q_r"][:n], e["dq"][:n]
    hidden = torch.maximum(q_r, q_r + dq * n_cols) <= least[row]
    key = 2 * row + hidden                                                  # the row's visible, then hidden
    order = torch.argsort(key, stable=True)                                 # each row's entries together
    first = lambda x: x[:n][order]                                          # noqa: E731  left edge (or shared)
    second = lambda x: x[n:][order]                                         # noqa: E731  right edge
    ul, ur, q_r, dq, coef_l = first(e["ul"]), first(e["ur"]), q_r[order], dq[order], coef_l[order]
    coef_r = None if coef_r is None else coef_r[order]
    # the columns of every row at once, rows after rows: (centre, [g, g · here], q shown), for the rows'
    # visible faces (wanted pixels) and for their hidden ones (wanted pixels of the background)
    columns = []
    for mask in (wanted, wanted & empty):
        ends = torch.cumsum(mask.sum(1), 0).tolist()
        columns.append((mask.nonzero()[:, 1].to(ul.dtype) + 0.5, rhs_all[mask], depth[mask], [0] + ends))
    L, R = torch.zeros_like(ul), torch.zeros_like(ul)                       # per entry: the sums left and right
    s0 = 0
    for k, count in enumerate(torch.bincount(key, minlength=2 * n_rows).tolist()):
        up, rhs, dep, ends = columns[k % 2]
        c0, c1 = ends[k // 2], ends[k // 2 + 1]                             # this row's columns
        if count and c1 > c0:
            step = max(1, CHUNK // (c1 - c0))                               # at most about CHUNK elements
            for a in range(s0, s0 + count, step):
                b = min(a + step, s0 + count)
                L[a:b], R[a:b] = _nmr_table(ul[a:b], ur[a:b], q_r[a:b], dq[a:b], coef_l[a:b],
                                            None if coef_r is None else coef_r[a:b], up[c0:c1], rhs[c0:c1].T,
                                            dep[c0:c1], band, reach)
        s0 += count
    # the left edge moves -u to cover a pixel on its left, the right edge +u (vertex weights w and 1 - w)
    w_l, w_r = first(e["s_e"]), second(e["s_e"])
    for vid, term in ((first(e["vid_a"]), -w_l * L), (first(e["vid_b"]), -(1 - w_l) * L),
                      (second(e["vid_a"]), w_r * R), (second(e["vid_b"]), (1 - w_r) * R)):
        out.index_add_(0, vid, term)


def _nmr_table(ul, ur, q_r, dq, coef_l, coef_r, up, rhs, dep, band, reach):
    """One row's table: Σ over the pixels left of each span, and right of it, farther than ``band`` (and at
    most ``reach``), of ``min(0, δᴾ · δI) / |δ|`` where the face's plane is nearer than the pixel's surface.
    ul, ur, q_r, dq: (n,) the spans and planes; coef_l, coef_r: (n, C + 1) [colour, -1] (coef_r None: the
    same colour both sides); up: (p,) the columns' centres; rhs: (C + 1, p) [g, g · here]; dep: (p,)
    what the pixels show (q). Returns L, R (n,). Masks are applied in place: few passes over the table."""
    off = torch.addr(q_r[:, None], dq, up) <= dep                           # (n, p) the plane not nearer
    if reach < math.inf:
        off |= torch.maximum(ul[:, None] - up, up - ur[:, None]) > reach     # or the pixel out of reach
    # min(0, δᴾ · δI), the sign rule: δᴾ · δI = g · colour - g · here, one matrix product
    dot_l = (coef_l @ rhs).clamp_(max=0)
    dot_r = dot_l if coef_r is None else (coef_r @ rhs).clamp_(max=0)
    sums = []
    for dot, dist in ((dot_l, ul[:, None] - up), (dot_r, up - ur[:, None])):   # |δ| left of the span; right
        skip = (dist <= band) | off                                         # the span, the other side, the band
        sums.append((dot / dist).masked_fill_(skip, 0.0).sum(1))            # (0/0 where skipped: replaced)
    return sums


def _row_plane(tu, tv, tq, vc):
    """The affine function through (tu_k, tv_k, tq_k), k = 0..2, on the line v = vc: ``q = q_r + dq u``.
    tu, tv, tq: (N, 3); vc: (N,). Returns q_r, dq (N,) each (0 for a degenerate triangle)."""
    e1u, e1v, e2u, e2v = tu[:, 1] - tu[:, 0], tv[:, 1] - tv[:, 0], tu[:, 2] - tu[:, 0], tv[:, 2] - tv[:, 0]
    d1, d2 = tq[:, 1] - tq[:, 0], tq[:, 2] - tq[:, 0]
    det = e1u * e2v - e1v * e2u
    det = torch.where(det == 0, torch.ones_like(det), det)
    du, dv = (d1 * e2v - d2 * e1v) / det, (d2 * e1u - d1 * e2u) / det       # the gradient of q on screen
    return tq[:, 0] + du * (0 - tu[:, 0]) + dv * (vc - tv[:, 0]), du
