"""3D Gaussian splatting in torch, float64 by default, readable (lecture 15).

A scene of N Gaussians: centres ``means`` (N, 3), standard deviations along each one's own axes ``scales``
(N, 3), orientations ``rotations`` (N, 4) as unit quaternions (w, x, y, z), ``opacities`` (N,) in [0, 1] and
``colors`` (N, 3). ``render_gaussians`` draws them with the rules of Kerbl et al.'s reference rasterizer
("3D Gaussian Splatting for Real-Time Radiance Field Rendering", SIGGRAPH 2023), evaluated at the course's pixel
centres (pixel (i, j) covers [j, j+1) × [i, i+1), its centre (j + ½, i + ½)):

1. **Cull** a Gaussian whose mean lies at most 0.2 in front of the camera (view-space depth z <= 0.2).
2. **3D covariance** ``Σ = R S Sᵀ Rᵀ``, R the rotation of the quaternion, S = diag(scales).
3. **2D covariance** by the projection's Jacobian at the mean: ``Σ₂ = J W Σ Wᵀ Jᵀ + 0.3 I`` (pixels²), W the
   camera's rotation and J the derivative of the pixel position with respect to the camera-space point,
   ``K₂ [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]`` (K₂ the upper-left 2 × 2 of K; ``K₂ [[1, 0, 0], [0, 1, 0]]`` for an
   orthographic camera). The 0.3 px² is the reference's low-pass filter: no Gaussian is thinner than a pixel's
   footprint. The projected mean is the mean's pixel position.
4. **Opacity at a pixel**: ``α = min(0.99, o · exp(-½ dᵀ Σ₂⁻¹ d))``, d the pixel centre minus the projected mean;
   a Gaussian is skipped at a pixel where α < 1/255.
5. **Compositing**, front to back in the order of the means' view-space depth (one order for the whole image:
   a visibility decision, lecture 15), ``C += c α T``, ``T ← T (1 - α)``, stopping before the Gaussian that would
   take the transmittance T below 1e-4 (that one is not added); then ``C + T · background``.

Two rules of the reference are left out, both choices of its tiling rather than of the image model: it clamps
x/z and y/z to 1.3 times the field of view before forming J (a guard for Gaussians far off screen), and it
evaluates a Gaussian only in the 16 × 16 tiles its 3-sigma box touches, so a pixel of a neighbouring tile, still
above the 1/255 cut, misses it. Here every Gaussian is evaluated wherever its α reaches 1/255: the image is the
same for every tile or chunk size (``tile``), which only skips Gaussians that cannot reach the cut in a tile.

Autograd differentiates every smooth part: the means, scales, rotations, opacities, colours and the camera's
K, R and t. It does not see the discontinuities, all decisions: the **depth order** (when two means swap depth,
the image jumps where both cover a pixel; lecture 15 measures it) and the **cut-offs** α < 1/255 and T < 1e-4
(``tests/test_splats.py`` measures the first). The clamp at α = 0.99 is continuous, a kink in the derivative.
"""
from __future__ import annotations


import math

import torch

from .tensors import _check_finite, as_tensor

__all__ = ["render_gaussians", "render_gaussians_volume", "quaternion_to_matrix", "covariance_3d",
           "project_gaussians", "swap_scene", "swap_study", "splat_volume_study", "splat_volume_causes", "splat_step",
           "SPLAT_STEPS", "CAUSES", "volume_strength", "NEAR", "ALPHA_MIN", "ALPHA_MAX", "T_MIN", "BLUR"]

NEAR = 0.2               # a mean closer than this (view-space depth) is culled
ALPHA_MIN = 1.0 / 255.0  # a Gaussian is skipped at a pixel where its alpha is below this
ALPHA_MAX = 0.99         # alpha is clamped to this
T_MIN = 1e-4             # compositing stops before the transmittance would fall below this
BLUR = 0.3               # px², added to the 2D covariance's diagonal (the reference's low-pass filter)


def quaternion_to_matrix(q) -> torch.Tensor:
    """(N, 3, 3) rotation matrices of unit quaternions q (N, 4), (w, x, y, z)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(q.shape[:-1] + (3, 3))


def covariance_3d(scales, rotations) -> torch.Tensor:
    """(N, 3, 3) ``Σ = R S Sᵀ Rᵀ`` (module docstring, step 2)."""
    M = quaternion_to_matrix(rotations) * scales[..., None, :]             # R S: column k scaled by s_k
    return M @ M.transpose(-1, -2)


def project_gaussians(means, scales, rotations, camera, *, blur: float = BLUR):
    """The Gaussians seen by ``camera``: (pixel means (N, 2), 2D covariances (N, 2, 2) with ``blur`` px² added to
    the diagonal (the reference's 0.3), view-space depths (N,)) (module docstring, steps 2-3), differentiable in
    everything."""
    K, R, t = camera.K.to(means), camera.R.to(means), camera.t.to(means)        # means' dtype and device
    cam = means @ R.T + t                                                   # (N, 3) camera space
    x, y, z = cam.unbind(-1)
    K2 = K[:2, :2]
    zero, one = torch.zeros_like(z), torch.ones_like(z)
    if camera.orthographic:
        P = torch.stack([one, zero, zero, zero, one, zero], -1).view(-1, 2, 3)
        xy = torch.stack([x, y], -1)
    else:
        inv = 1 / z
        P = torch.stack([inv, zero, -x * inv * inv, zero, inv, -y * inv * inv], -1).view(-1, 2, 3)
        xy = torch.stack([x * inv, y * inv], -1)
    J = K2 @ P                                                              # (N, 2, 3)
    T = J @ R                                                               # J W
    cov2 = T @ covariance_3d(scales, rotations) @ T.transpose(-1, -2)
    cov2 = cov2 + float(blur) * torch.eye(2, dtype=means.dtype, device=means.device)
    mean2 = xy @ K2.T + K[:2, 2]
    return mean2, cov2, z


def _check(means, scales, rotations, opacities, colors, background):
    m = as_tensor(means, name="means")
    if m.dim() != 2 or m.shape[1] != 3:
        raise ValueError(f"means must have shape (N, 3), got {tuple(m.shape)}")
    N = m.shape[0]
    dtype = m.dtype if m.dtype in (torch.float32, torch.float64) else torch.float64
    out = [m.to(dtype)]
    for value, name, shape in ((scales, "scales", (N, 3)), (rotations, "rotations", (N, 4)),
                               (opacities, "opacities", (N,)), (colors, "colors", (N, 3))):
        v = as_tensor(value, dtype=dtype, device=m.device, name=name)
        if tuple(v.shape) != shape:
            raise ValueError(f"{name} must have shape {shape}, got {tuple(v.shape)}")
        out.append(v)
    for v, name in zip(out, ("means", "scales", "rotations", "opacities", "colors")):
        _check_finite(v, name)
    m, s, q, o, c = out
    if N and bool((s.detach() <= 0).any()):
        raise ValueError("scales must be positive (a Gaussian's standard deviations along its axes)")
    if N and bool(((o.detach() < 0) | (o.detach() > 1)).any()):
        raise ValueError("opacities must lie in [0, 1]")
    if N:
        norm = q.detach().norm(dim=1)
        if bool(((norm - 1).abs() > 1e-6).any()):
            raise ValueError(f"rotations must be unit quaternions (w, x, y, z): a norm is {float(norm.max()):.6g}; "
                             "normalise them (q / q.norm(dim=1, keepdim=True)) before rendering")
    bg = as_tensor(background, dtype=dtype, device=m.device, name="background")
    if tuple(bg.shape) != (3,):
        raise ValueError(f"background must have shape (3,), got {tuple(bg.shape)}")
    return m, s, q, o, c, bg


def render_gaussians(means, scales, rotations, opacities, colors, camera, background=(0.0, 0.0, 0.0), *,
                     tile: int = 16) -> torch.Tensor:
    """The image (H, W, 3) of N Gaussians by Kerbl et al.'s rules (module docstring), at the pixel centres.

    means (N, 3), scales (N, 3) > 0, rotations (N, 4) unit quaternions (w, x, y, z), opacities (N,) in [0, 1],
    colors (N, 3); camera a course ``Camera``; background (3,). Computed in the means' dtype (float64 unless
    they are float32); differentiable by autograd in every input and the camera's K, R and t, except across the
    decisions (depth order, cut-offs). ``tile``: pixels a side of the blocks the image is composited in (each
    block skips the Gaussians that cannot reach α = 1/255 in it); the image does not depend on it.
    """
    m, s, q, o, c, bg = _check(means, scales, rotations, opacities, colors, background)
    tile = int(tile)
    if tile < 1:
        raise ValueError(f"tile must be a positive integer, got {tile!r}")
    H, W = camera.height, camera.width
    image = bg.expand(H, W, 3).clone()
    if m.shape[0] == 0:
        return image
    mean2, cov2, z = project_gaussians(m, s, q, camera)
    order = torch.argsort(z.detach(), stable=True)                           # front to back
    keep = order[z.detach()[order] > NEAR]                                    # culled: too near (or behind)
    if keep.numel() == 0:
        return image
    mean2, cov2, o, c = mean2[keep], cov2[keep], o[keep], c[keep]
    a, b, d = cov2[:, 0, 0], cov2[:, 0, 1], cov2[:, 1, 1]
    det = a * d - b * b
    conic = torch.stack([d / det, -b / det, a / det], -1)                    # Σ₂⁻¹ as (A, B, C)
    # where α can reach 1/255: o exp(-q/2) >= 1/255, q <= 2 ln(255 o); the ellipse's box, padded a hair
    reach = 2 * torch.log((o.detach() / ALPHA_MIN).clamp_min(1.0))
    half_w = (reach * a.detach()).sqrt() * (1 + 1e-9) + 1e-9
    half_h = (reach * d.detach()).sqrt() * (1 + 1e-9) + 1e-9
    lo = torch.stack([mean2.detach()[:, 0] - half_w, mean2.detach()[:, 1] - half_h], -1)
    hi = torch.stack([mean2.detach()[:, 0] + half_w, mean2.detach()[:, 1] + half_h], -1)
    rows = []
    for i0 in range(0, H, tile):
        row = []
        for j0 in range(0, W, tile):
            i1, j1 = min(i0 + tile, H), min(j0 + tile, W)
            near = ((hi[:, 0] >= j0 + 0.5) & (lo[:, 0] <= j1 - 0.5) & (hi[:, 1] >= i0 + 0.5)
                    & (lo[:, 1] <= i1 - 0.5)).nonzero().squeeze(1)
            row.append(_composite(mean2[near], conic[near], o[near], c[near], bg, i0, i1, j0, j1))
        rows.append(torch.cat(row, 1))
    return torch.cat(rows, 0)


def _composite(mean2, conic, o, c, bg, i0, i1, j0, j1):
    """(i1 - i0, j1 - j0, 3) the block's pixels composited front to back (module docstring, steps 4-5) from the
    Gaussians given, in depth order."""
    dtype = mean2.dtype
    ii = torch.arange(i0, i1, dtype=dtype, device=mean2.device) + 0.5
    jj = torch.arange(j0, j1, dtype=dtype, device=mean2.device) + 0.5
    py, px = torch.meshgrid(ii, jj, indexing="ij")
    p = torch.stack([px.reshape(-1), py.reshape(-1)], -1)                     # (P, 2) pixel centres
    if mean2.shape[0] == 0:
        return bg.expand(i1 - i0, j1 - j0, 3).clone()
    dx = p[:, None, 0] - mean2[None, :, 0]                                    # (P, N)
    dy = p[:, None, 1] - mean2[None, :, 1]
    power = -0.5 * (conic[:, 0] * dx * dx + 2 * conic[:, 1] * dx * dy + conic[:, 2] * dy * dy)
    alpha = (o * torch.exp(power)).clamp(max=ALPHA_MAX)
    alpha = torch.where(alpha >= ALPHA_MIN, alpha, torch.zeros_like(alpha))  # skipped where below 1/255
    clear = 1 - alpha
    before = torch.cumprod(torch.cat([torch.ones_like(clear[:, :1]), clear[:, :-1]], 1), 1)   # T before each
    stop = (before * clear).detach() < T_MIN                                  # this one would take T below 1e-4
    done = torch.cummax(stop.to(torch.int8), 1).values.bool()                 # it and every one after: not added
    weight = torch.where(done, torch.zeros_like(alpha), alpha * before)
    last = torch.where(done, torch.ones_like(clear), clear).prod(1)           # T after the added ones
    color = weight @ c + last[:, None] * bg
    return color.view(i1 - i0, j1 - j0, 3)


# ------------------------------------------------------------------------------- the same Gaussians as a volume

def render_gaussians_volume(means, scales, rotations, opacities, colors, camera, background=(0.0, 0.0, 0.0), *,
                            samples: int = 256, near: float | None = None, far: float | None = None,
                            chunk: int = 4096) -> torch.Tensor:
    """(H, W, 3) the Gaussians as a participating medium, ray-marched (no sort, no projection): the density
    ``σ(x) = Σ_i κ_i exp(-½ (x - μ_i)ᵀ Σ_i⁻¹ (x - μ_i))``, the colour where it emits ``Σ_i σ_i c_i / σ``, and
    NeRF's quadrature (``course.volume``) with ``samples`` equal steps from ``near`` to ``far`` along each
    pixel-centre ray (default: the span of the means' depths, widened by 6 of the largest standard deviation).

    ``κ_i`` makes one Gaussian alone look as the splat does at its centre: the optical depth along the ray from
    the camera through its mean is ``κ_i sqrt(2π / (uᵀ Σ_i⁻¹ u))``, u the ray's unit direction (the 3D Gaussian integrated along the line), set
    to ``-ln(1 - o_i)`` so that the opacity there is o_i. Elsewhere the two differ where splatting approximates:
    the cut-offs, the 0.3 px² blur, ``1 - e^{-τ}`` against the splat's linear ``o e^{-q/2}`` away from the centre,
    the projection linearised at the mean (J), and each Gaussian composited whole at its mean's depth (two that
    interpenetrate are drawn one over the other); ``splat_volume_causes`` measures each, lecture 15 prints them. Differentiable; float64 unless the means are
    float32."""
    m, s, q, o, c, bg = _check(means, scales, rotations, opacities, colors, background)
    n = int(samples)
    if n < 1:
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    H, W = camera.height, camera.width
    origins, directions = camera.rays()
    origins = origins.reshape(-1, 3).to(m)
    directions = directions.reshape(-1, 3).to(m)
    directions = directions / directions.norm(dim=1, keepdim=True)
    if m.shape[0] == 0:
        return bg.expand(H, W, 3).clone()
    inv = torch.linalg.inv(covariance_3d(s, q))                                  # (N, 3, 3)
    eye = -camera.R.to(m).T @ camera.t.to(m)
    kappa = _strength_in_view(camera, m, inv, o)
    depth = (m - eye) @ camera.R.to(m)[2]
    pad = 6 * float(s.detach().max())                                          # the tails beyond: 2e-9 of τ
    lo = float(depth.detach().min()) - pad if near is None else float(near)
    hi = float(depth.detach().max()) + pad if far is None else float(far)
    lo = max(lo, 1e-6)
    out = []
    for start in range(0, origins.shape[0], chunk):
        o_r, d_r = origins[start:start + chunk], directions[start:start + chunk]
        cos = d_r @ camera.R.to(m)[2]                                    # depth per unit along the ray
        s0, s1 = lo / cos, hi / cos
        delta = (s1 - s0) / n                                                  # (R,)
        t = s0[:, None] + (torch.arange(n, dtype=m.dtype, device=m.device) + 0.5)[None] * delta[:, None]   # (R, n)
        x = o_r[:, None, :] + t[..., None] * d_r[:, None, :]                   # (R, n, 3)
        diff = x[:, :, None, :] - m[None, None]                                # (R, n, N, 3)
        qd = torch.einsum("rsni,nij,rsnj->rsn", diff, inv, diff)
        sig_i = kappa * torch.exp(-0.5 * qd)                                   # (R, n, N)
        sig = sig_i.sum(-1)
        emit = sig_i @ c                                                       # (R, n, 3) = σ · colour
        tau = sig * delta[:, None]
        before = torch.exp(-torch.cumsum(torch.cat([torch.zeros_like(tau[:, :1]), tau[:, :-1]], 1), 1))
        alpha = -torch.expm1(-tau)
        colour = emit / sig.clamp_min(1e-300)[..., None]
        image = ((before * alpha)[..., None] * colour).sum(1) + torch.exp(-tau.sum(1))[:, None] * bg
        out.append(image)
    return torch.cat(out).view(H, W, 3)


# ------------------------------------------------------------------------------- the depth swap, measured

def swap_scene(size: int = 16):
    """Two overlapping Gaussians, red and blue: ``(params, camera, toward, swap)`` where the blue one's mean moves
    by ``s · toward`` (the unit view direction) and ``swap`` is the s at which the two means' view depths are equal
    (blue in front for s below it, red above; there the depth order, and the image, jump)."""
    from .camera import Camera
    camera = Camera.look_at((0.4, 0.6, 4.0), (0.0, 0.0, 0.0), fov_y=45.0, width=size, height=size,
                            dtype=torch.float64)
    eye = -camera.R.T @ camera.t
    toward = -eye / eye.norm()
    means = torch.stack([torch.zeros(3, dtype=torch.float64), torch.tensor([0.05, 0.0, 0.0], dtype=torch.float64)])
    params = (means, torch.full((2, 3), 0.5, dtype=torch.float64),
              torch.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]], dtype=torch.float64),
              torch.tensor([0.8, 0.8], dtype=torch.float64), torch.tensor([[1.0, 0, 0], [0, 0, 1.0]], dtype=torch.float64))
    swap = float((means[0] - means[1]) @ camera.R[2])
    return params, camera, toward, swap


def swap_study(width: float = 0.05, samples: int = 64, size: int = 16) -> dict:
    """What autograd misses at a depth swap, and what a boundary term adds (lecture 15). ``L(s)``: the red
    channel of ``swap_scene``'s image summed, the blue Gaussian moved by s. L jumps by ``jump`` at the swap s*.
    Smooth L over a window, ``L_w(s*) = mean of L over [s* - w, s* + w]``: its derivative is exactly
    ``(L(s* + w) - L(s* - w)) / 2w`` (``smoothed``); autograd averaged over the window (``autograd``, a midpoint
    rule with ``samples`` points) differentiates L's smooth pieces only, and misses ``jump / 2w`` (``boundary``),
    the jump times the density of s at the swap: the boundary term. Returns those numbers (floats)."""
    params, camera, toward, swap = swap_scene(size)
    means = params[0]

    def loss(s):
        m = torch.stack([means[0], means[1] + s * toward])
        return render_gaussians(m, *params[1:], camera)[..., 0].sum()
    w = float(width)
    eps = 1e-9
    jump = float(loss(torch.tensor(swap + eps)) - loss(torch.tensor(swap - eps)))
    smoothed = float(loss(torch.tensor(swap + w)) - loss(torch.tensor(swap - w))) / (2 * w)
    grads = []
    for k in range(int(samples)):
        s = torch.tensor(swap - w + (k + 0.5) * 2 * w / samples, dtype=torch.float64, requires_grad=True)
        g, = torch.autograd.grad(loss(s), s)
        grads.append(float(g))
    autograd = sum(grads) / len(grads)
    return dict(jump=jump, smoothed=smoothed, autograd=autograd, boundary=jump / (2 * w),
                corrected=autograd + jump / (2 * w))


def _volume_scenes(size: int):
    """The three scenes of ``splat_volume_study``: {name: (means, scales, rotations, opacities, colors, camera)}."""
    from .camera import Camera
    narrow = Camera.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov_y=30.0, width=size, height=size,
                            dtype=torch.float64)
    wide = Camera.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov_y=90.0, width=size, height=size,
                          dtype=torch.float64)
    one = torch.tensor([[1.0, 0, 0, 0]])
    scenes = {
        "alone": (torch.zeros(1, 3), torch.tensor([[0.3, 0.2, 0.25]]), one, torch.tensor([0.6]),
                  torch.tensor([[1.0, 0.5, 0.2]]), narrow),
        "interpenetrating": (torch.tensor([[0.0, 0.0, 0.0], [0.05, 0.0, -0.02]]),
                             torch.tensor([[0.3, 0.3, 0.3], [0.3, 0.3, 0.3]]), one.expand(2, 4), torch.tensor([0.6, 0.6]),
                             torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), narrow),
        "off_axis": (torch.tensor([[2.6, 2.6, 0.0]]), torch.tensor([[0.3, 0.2, 0.25]]), one, torch.tensor([0.6]),
                     torch.tensor([[1.0, 0.5, 0.2]]), wide),
    }
    return {name: tuple(v.to(torch.float64) for v in scene[:5]) + (scene[5],) for name, scene in scenes.items()}


def splat_volume_study(size: int = 24, samples: int = 256) -> dict:
    """Where splatting's approximations show (lecture 15): ``render_gaussians`` against
    ``render_gaussians_volume`` of the same Gaussians, max |difference| over the image, in three scenes:

    * ``alone``: one Gaussian in the middle of a 30° view (standard deviations 2.2-3.4 px on screen);
    * ``interpenetrating``: two Gaussians of different colours at almost the same place;
    * ``off_axis``: one Gaussian near the corner of a wide (90°) view (0.7-1.1 px).
    Returns {scene: max |difference|} (floats). ``splat_volume_causes`` splits each between the causes (measured:
    the falloff decides ``alone``, the sort ``interpenetrating``, the 0.3 px² blur ``off_axis``, where the
    linearised projection is ten times what it is in ``alone``)."""
    out = {}
    for name, (m, s, q, o, c, cam) in _volume_scenes(size).items():
        a = render_gaussians(m, s, q, o, c, cam)
        b = render_gaussians_volume(m, s, q, o, c, cam, samples=samples)
        out[name] = float((a - b).abs().max())
    return out


SPLAT_STEPS = ("reference", "no cut-offs", "no blur", "exponential falloff", "exact footprint")
CAUSES = ("cut-offs", "blur", "falloff", "linearisation", "sort")


def splat_step(means, scales, rotations, opacities, colors, camera, background=(0.0, 0.0, 0.0), *,
               step: str = "exact footprint") -> torch.Tensor:
    """(H, W, 3) the splat with splatting's approximations taken away one at a time, in the order of
    ``SPLAT_STEPS`` (each step keeps the ones before it; every one composites whole Gaussians in the order of
    their means' depth, culled at 0.2):

    * ``"reference"``: ``render_gaussians``;
    * ``"no cut-offs"``: ``α = o e^{-q/2}``, never skipped below 1/255 nor clamped at 0.99, no early stop;
    * ``"no blur"``: the 2D covariance without the 0.3 px²;
    * ``"exponential falloff"``: ``α = 1 - (1 - o)^{e^{-q/2}}``, the opacity a medium of the splat's
      footprint would have (``1 - e^{-τ}`` with τ proportional to the Gaussian, ``-ln(1 - o)`` at its centre);
    * ``"exact footprint"``: ``α = 1 - e^{-κ ∫ G}``, the 3D Gaussian integrated along each pixel's ray in closed
      form (``∫ exp(-½ (x - μ)ᵀ Σ⁻¹ (x - μ)) dt = sqrt(2π / a) exp(-½ (c - b² / a))``, a = uᵀ Σ⁻¹ u,
      b = uᵀ Σ⁻¹ (o - μ), c = (o - μ)ᵀ Σ⁻¹ (o - μ) for the ray o + t u) with ``volume_strength``'s κ: no
      linearised projection. What is left against ``render_gaussians_volume`` is the sort (and its quadrature).

    For one Gaussian in an orthographic view the last two steps give the same image: there the projection is
    linear and the footprint exactly Gaussian (``tests/test_splats.py``)."""
    if step not in SPLAT_STEPS:
        raise ValueError(f"step must be one of {SPLAT_STEPS}, got {step!r}")
    if step == "reference":
        return render_gaussians(means, scales, rotations, opacities, colors, camera, background)
    m, s, q, o, c, bg = _check(means, scales, rotations, opacities, colors, background)
    H, W = camera.height, camera.width
    k = SPLAT_STEPS.index(step)
    mean2, cov2, z = project_gaussians(m, s, q, camera, blur=BLUR if k < 2 else 0.0)
    order = torch.argsort(z.detach(), stable=True)
    keep = order[z.detach()[order] > NEAR]
    if keep.numel() == 0:
        return bg.expand(H, W, 3).clone()
    if k < 4:
        jj, ii = torch.meshgrid(torch.arange(W, dtype=m.dtype, device=m.device) + 0.5,
                                torch.arange(H, dtype=m.dtype, device=m.device) + 0.5,
                                indexing="xy")
        d = torch.stack([jj.reshape(-1), ii.reshape(-1)], -1)[:, None, :] - mean2[keep][None]     # (P, N, 2)
        inv2 = torch.linalg.inv(cov2[keep])
        gauss = torch.exp(-0.5 * torch.einsum("pni,nij,pnj->pn", d, inv2, d))
        ok = o[keep]
        alpha = ok * gauss if k < 3 else -torch.expm1(gauss * torch.log1p(-ok.clamp(max=1 - 1e-12)))
    else:
        origins, directions = camera.rays()
        origins = origins.reshape(-1, 3).to(m)
        u = directions.reshape(-1, 3).to(m)
        u = u / u.norm(dim=1, keepdim=True)
        inv = torch.linalg.inv(covariance_3d(s[keep], q[keep]))                   # (N, 3, 3)
        kappa = _strength_in_view(camera, m[keep], inv, o[keep])
        e = origins[:, None, :] - m[keep][None]                                   # (P, N, 3)
        a = torch.einsum("pi,nij,pj->pn", u, inv, u)
        b = torch.einsum("pi,nij,pnj->pn", u, inv, e)
        cq = torch.einsum("pni,nij,pnj->pn", e, inv, e)
        line = torch.sqrt(2 * math.pi / a) * torch.exp(-0.5 * (cq - b * b / a).clamp_min(0))
        alpha = -torch.expm1(-kappa * line)
    before = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1 - alpha[:, :-1]], 1), 1)
    color = (alpha * before) @ c[keep] + (before[:, -1] * (1 - alpha[:, -1]))[:, None] * bg
    return color.view(H, W, 3)


def splat_volume_causes(size: int = 24, samples: int = 256) -> dict:
    """``splat_volume_study`` split by cause: for each scene, max |difference| over the image between consecutive
    steps of ``splat_step`` (``"cut-offs"``: the reference against no cut-offs; ``"blur"``; ``"falloff"``;
    ``"linearisation"``: the linearised footprint against the exact one), then ``"sort"``: the exact footprint
    composited whole in depth order against ``render_gaussians_volume`` (the medium mixes by density);
    ``"quadrature"``: the medium at ``samples`` against 4 × ``samples`` steps a ray (what the sort's number
    cannot tell from it); ``"total"``: the reference against the medium, as ``splat_volume_study``;
    ``"footprint_px"``: (smallest, largest) standard deviation of the scene's splats on screen in pixels, the blur
    left out (the 0.3 px² matters where this is about a pixel). The five causes' images sum to the total's
    (telescoping); their maxima bound it. Returns {scene: {name: float, "footprint_px": (float, float)}}."""
    out = {}
    for name, (m, s, q, o, c, cam) in _volume_scenes(size).items():
        images = [splat_step(m, s, q, o, c, cam, step=step) for step in SPLAT_STEPS]
        medium = render_gaussians_volume(m, s, q, o, c, cam, samples=samples)
        finer = render_gaussians_volume(m, s, q, o, c, cam, samples=4 * samples)
        images.append(medium)
        row = {cause: float((images[k + 1] - images[k]).abs().max()) for k, cause in enumerate(CAUSES)}
        row["quadrature"] = float((medium - finer).abs().max())
        row["total"] = float((images[-1] - images[0]).abs().max())
        spread = torch.linalg.eigvalsh(project_gaussians(m, s, q, cam, blur=0.0)[1]).sqrt()
        row["footprint_px"] = (float(spread.min()), float(spread.max()))
        out[name] = row
    return out


def volume_strength(means, scales, rotations, opacities, eye) -> torch.Tensor:
    """(N,) each Gaussian's peak density κ in ``render_gaussians_volume``: the optical depth along the ray from
    ``eye`` (3,) through its mean, ``κ sqrt(2π / (uᵀ Σ⁻¹ u))`` (u the ray's unit direction: the 3D Gaussian
    integrated along the line), set to ``-ln(1 - o)`` so that the ray sees opacity o there."""
    toward = means - eye
    return _strength(torch.linalg.inv(covariance_3d(scales, rotations)), opacities,
                     toward / toward.norm(dim=1, keepdim=True))


def _strength_in_view(camera, means, inv, opacities):
    """κ of ``volume_strength`` for ``camera``'s ray through each mean: from its eye, or along its view axis for
    an orthographic camera (parallel rays)."""
    R = camera.R.to(means)
    if camera.orthographic:
        toward = R[2].expand(means.shape[0], 3)
    else:
        toward = means + R.T @ camera.t.to(means)                                # the mean minus the eye
        toward = toward / toward.norm(dim=1, keepdim=True)
    return _strength(inv, opacities, toward)


def _strength(inv, opacities, toward):
    """κ of ``volume_strength`` from the inverse covariances (N, 3, 3) and the rays' unit directions (N, 3)."""
    line = torch.einsum("ni,nij,nj->n", toward, inv, toward)
    return -torch.log1p(-opacities.clamp(max=1 - 1e-12)) / torch.sqrt(2 * math.pi / line)
