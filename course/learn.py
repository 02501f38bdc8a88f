"""Single-image mesh reconstruction through the renderer (lecture 13; Kato, Ushiku and Harada 2018, section 4.2).

A small convolutional encoder reads one image of a shape and predicts how a sphere deforms into it: an
offset per vertex of an icosphere, and a per-axis scale and a translation of the whole. Nothing 3D
supervises it. The predicted mesh is rendered by soft rasterization (``soft.soft_rasterize``, all views in
one call: a camera batch) from two or more known views, and compared with the shape's silhouettes there by
Kato et al.'s IoU loss, plus their smoothness loss so the sphere deforms without folding::

    image (H, W, 3) ─encoder─▶ code (128,) ─heads─▶ verts = (sphere + offsets) · scale + translation (V, 3)
    verts ─soft_rasterize(views)─▶ (Nv, H, W) ─silhouette_iou_loss(·, targets)─▶ + λ smoothness_loss

The views and the data come from ``course.shape_data`` (image of view 0 in, silhouettes of all views out).
The soft silhouette needs a blur of about a pixel to pass gradients from pixels the mesh misses: σ = 3e-3 in
the NDC units of ``soft_rasterize`` is σ_px = σ W² / 4 ≈ 0.8 px² at W = 32.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from .losses import silhouette_iou_loss, smoothness_loss
from .mesh import Mesh
from .models import icosphere
from .soft import soft_rasterize
from .tensors import _check_count, _check_real

__all__ = ["ReconstructionSettings", "MeshReconstructor", "reconstruction_loss", "train_step"]


@dataclass(frozen=True)
class ReconstructionSettings:
    """The network and loss settings. size: input image side (a multiple of 8); subdivisions: of the icosphere
    template (2: 162 vertices, 320 faces); radius: the template's; sigma: soft rasterization's sharpness (NDC);
    smoothness: the weight λ of the smoothness loss; seed: of the initial weights."""
    size: int = 32
    subdivisions: int = 2
    radius: float = 0.6
    sigma: float = 3e-3
    smoothness: float = 1e-3
    seed: int = 0


class MeshReconstructor(torch.nn.Module):
    """An encoder from one image to the vertices of a deformed icosphere. Faces are the template's (``faces``).

    Three stride-2 3 × 3 convolutions (16, 32, 64 channels, ReLU) take the (B, H, W, 3) images to (B, 64, H/8,
    W/8), a linear layer to a 128-d code, then three linear heads: offsets (V × 3), log-scale (3) and
    translation (3). The heads start at zero (offsets nearly so), so every prediction starts as the template
    sphere: the loss's first gradients then come from the silhouettes, not from a random mesh.
    """

    def __init__(self, settings: ReconstructionSettings = ReconstructionSettings()):
        super().__init__()
        size = _check_count(settings.size, "size")
        if size % 8:
            raise ValueError(f"size must be a multiple of 8 (three stride-2 convolutions), got {size}")
        self.settings = settings
        template = icosphere(_check_count(settings.subdivisions, "subdivisions", minimum=0),
                             _check_real(settings.radius, "radius", low=0, low_open=True), dtype=torch.float32)
        self.register_buffer("template", template.verts)              # (V, 3)
        self.register_buffer("faces", template.faces)                 # (F, 3)
        V = template.num_verts
        with torch.random.fork_rng(devices=[]):                        # seeded weights, global state restored
            torch.manual_seed(_check_count(settings.seed, "seed", minimum=0))
            self.encoder = torch.nn.Sequential(
                torch.nn.Conv2d(3, 16, 3, stride=2, padding=1), torch.nn.ReLU(),   # (B, 16, H/2, W/2)
                torch.nn.Conv2d(16, 32, 3, stride=2, padding=1), torch.nn.ReLU(),  # (B, 32, H/4, W/4)
                torch.nn.Conv2d(32, 64, 3, stride=2, padding=1), torch.nn.ReLU(),  # (B, 64, H/8, W/8)
                torch.nn.Flatten(), torch.nn.Linear(64 * (size // 8) ** 2, 128), torch.nn.ReLU())
            self.offsets = torch.nn.Linear(128, V * 3)
            self.log_scale = torch.nn.Linear(128, 3)
            self.translation = torch.nn.Linear(128, 3)
        with torch.no_grad():
            self.offsets.weight.mul_(1e-2), self.offsets.bias.zero_()
            for head in (self.log_scale, self.translation):
                head.weight.zero_(), head.bias.zero_()

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """(B, V, 3) predicted vertices (world space) from images (B, H, W, 3) in [0, 1], H = W = size."""
        if images.ndim != 4 or images.shape[1:] != (self.settings.size, self.settings.size, 3):
            raise ValueError(f"images must be (B, {self.settings.size}, {self.settings.size}, 3), got shape "
                             f"{tuple(images.shape)}")
        B = images.shape[0]
        code = self.encoder(images.permute(0, 3, 1, 2))               # (B, 128) from (B, 3, H, W)
        offsets = self.offsets(code).view(B, -1, 3)                   # (B, V, 3)
        scale = torch.exp(self.log_scale(code))[:, None]              # (B, 1, 3) per axis, positive
        return (self.template + offsets) * scale + self.translation(code)[:, None]


def reconstruction_loss(verts: torch.Tensor, faces: torch.Tensor, cameras, targets: torch.Tensor, *,
                        sigma: float = 3e-3, smoothness: float = 1e-3) -> tuple[torch.Tensor, torch.Tensor]:
    """(loss, per-shape IoU loss (B,)): the mean over the B shapes of the silhouette IoU loss averaged over the
    Nv views plus ``smoothness`` × ``smoothness_loss``.

    verts: (B, V, 3) predicted vertices; faces: (F, 3); cameras: list of Nv Camera (one image size H × W);
    targets: (B, Nv, H, W) silhouettes in [0, 1]. Each shape's views are one ``soft_rasterize`` call (back
    faces kept: a deforming sphere may fold, and its silhouette should still count every face).
    """
    if verts.ndim != 3 or targets.ndim != 4 or targets.shape[:2] != (verts.shape[0], len(cameras)):
        raise ValueError(f"need verts (B, V, 3) and targets (B, Nv={len(cameras)}, H, W), got "
                         f"{tuple(verts.shape)} and {tuple(targets.shape)}")
    iou_losses, smooth = [], []
    for b in range(verts.shape[0]):
        mesh = Mesh(verts[b], faces)
        sils = soft_rasterize(mesh, list(cameras), mode="silhouette", sigma=sigma, cull_backfaces=False)  # (Nv,H,W)
        iou_losses.append(silhouette_iou_loss(sils, targets[b].to(sils.dtype), reduction="mean"))
        smooth.append(smoothness_loss(verts[b], faces))
    iou_losses = torch.stack(iou_losses)                              # (B,)
    return iou_losses.mean() + smoothness * torch.stack(smooth).mean(), iou_losses.detach()


def train_step(model: MeshReconstructor, optimizer: torch.optim.Optimizer, images: torch.Tensor,
               silhouettes: torch.Tensor, cameras) -> float:
    """One optimisation step on a batch: images (B, H, W, 3) in, silhouettes (B, Nv, H, W) of ``cameras`` as
    targets. Returns the loss before the step."""
    optimizer.zero_grad()
    verts = model(images)
    loss, _ = reconstruction_loss(verts, model.faces, cameras, silhouettes, sigma=model.settings.sigma,
                                  smoothness=model.settings.smoothness)
    loss.backward()
    optimizer.step()
    return float(loss.detach())
