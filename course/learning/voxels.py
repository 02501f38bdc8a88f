"""A voxel network trained through a differentiable projection (lecture 13's voxel row of Table 1; Yan et al. 2016).

Kato et al.'s Table 1 sets their mesh network against a voxel network trained on the same silhouettes: Yan et al.'s
perspective transformer nets (NeurIPS 2016). It reads one image, predicts an occupancy grid, and is supervised
through a *projection* of that grid: each pixel of a known view looks along its ray and sees the largest occupancy
it passes (a max over samples of the grid, trilinearly interpolated). No 3D supervision, as for the mesh network::

    image (H, W, 3) ─encoder─▶ code ─decoder─▶ occupancy (R, R, R) in [0, 1]
    occupancy ─project_occupancy(views)─▶ (Nv, H, W) ─silhouette_iou_loss(·, targets)

* ``VoxelReconstructor``: the mesh network's encoder (``reconstruction.image_encoder``, the same layers, so the
  two differ only in what they decode), a linear layer to a 4³ grid of 16 channels and three transposed 3D
  convolutions up to R = 32. Its logits start as a sphere of the mesh network's template radius (the decoder's
  last layer starts near zero), so both networks start from the same shape. Entry [i, j, k] is the voxel centred
  at (x_i, y_j, z_k), as ``data.voxelize``.
* ``project_occupancy(occupancy, cameras, samples=64)``: the projection, (B, Nv, H, W) in [0, 1]; each shape's
  own cameras, or one list for all.
* ``train_voxel_reconstructor`` the same loop as ``train_reconstructor`` (the same batches, views, learning-rate
  schedule), ``voxel_mesh`` the surface of a predicted grid (surface nets at occupancy 0.5, ``inverse.carve``)
  for the surface metrics, ``save_voxel_reconstructor`` / ``load_voxel_reconstructor``.
"""
from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F

from ..inverse.carve import surface_nets
from ..inverse.losses import silhouette_iou_loss
from ..tensors import _check_count, _check_real
from .reconstruction import _per_shape_cameras, image_encoder, network_images, training_batches

__all__ = ["VoxelSettings", "VoxelReconstructor", "project_occupancy", "voxel_loss", "train_voxel_reconstructor",
           "voxel_mesh", "save_voxel_reconstructor", "load_voxel_reconstructor", "load_pretrained_voxel_reconstructor"]

PRETRAINED = Path(__file__).parents[1] / "data" / "voxel_reconstructor.pt"


@dataclass(frozen=True)
class VoxelSettings:
    """size: input image side (a multiple of 8); resolution: the grid's side R (a multiple of 4 and at least 8;
    32, the evaluation's); code: the encoder's output length (the mesh network's); radius: the starting
    sphere's (the mesh network's template); samples: points a pixel's ray takes in the projection; seed: of the
    initial weights."""
    size: int = 32
    resolution: int = 32
    code: int = 64
    radius: float = 0.6
    samples: int = 64
    seed: int = 0


class VoxelReconstructor(torch.nn.Module):
    """An encoder from one image to an occupancy grid over [-1, 1]³ (``forward``: probabilities (B, R, R, R))."""

    def __init__(self, settings: VoxelSettings = VoxelSettings()):
        super().__init__()
        size, R = _check_count(settings.size, "size"), _check_count(settings.resolution, "resolution", minimum=8)
        if size % 8:
            raise ValueError(f"size must be a multiple of 8 (three stride-2 convolutions), got {size}")
        if R % 4:
            raise ValueError(f"resolution must be a multiple of 4 (two doublings above the first grid), got {R}")
        _check_count(settings.samples, "samples", minimum=2)
        self.settings = settings
        radius = _check_real(settings.radius, "radius", low=0, low_open=True)
        centres = -1 + (torch.arange(R, dtype=torch.float32) + 0.5) * (2 / R)
        r = torch.stack(torch.meshgrid(centres, centres, centres, indexing="ij"), -1).norm(dim=-1)
        self.register_buffer("template", 4 * (radius - r) / (2 / R))  # logits: ±4 a voxel from the sphere
        self.first = R // 8                                              # 4 at R = 32: three doublings to R
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(_check_count(settings.seed, "seed", minimum=0))
            self.encoder = image_encoder(size, _check_count(settings.code, "code"))
            self.grid = torch.nn.Linear(settings.code, 16 * self.first ** 3)
            self.decoder = torch.nn.Sequential(
                torch.nn.ReLU(),
                torch.nn.ConvTranspose3d(16, 32, 4, stride=2, padding=1), torch.nn.ReLU(),   # (B, 32, R/4, ...)
                torch.nn.ConvTranspose3d(32, 16, 4, stride=2, padding=1), torch.nn.ReLU(),   # (B, 16, R/2, ...)
                torch.nn.ConvTranspose3d(16, 1, 4, stride=2, padding=1))                     # (B, 1, R, R, R)
        with torch.no_grad():
            last = self.decoder[-1]
            last.weight.mul_(1e-2), last.bias.zero_()

    def logits(self, images) -> torch.Tensor:
        """(B, R, R, R) occupancy logits from images (B, H, W, 3) in [0, 1] (``reconstruction.network_images``:
        any float dtype, numpy too, uint8 divided by 255)."""
        images = network_images(images, self.settings.size, self.template.dtype)
        code = self.encoder(images.permute(0, 3, 1, 2))
        n = self.first
        out = self.decoder(self.grid(code).view(-1, 16, n, n, n))[:, 0]
        return out + self.template

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """(B, R, R, R) occupancy probabilities, entry [i, j, k] the voxel at (x_i, y_j, z_k)."""
        return torch.sigmoid(self.logits(images))


def _ray_samples(camera, samples: int, dtype) -> torch.Tensor:
    """(H W, S, 3) points along each pixel-centre ray of ``camera``, spaced evenly over the stretch of the ray
    that can meet the cube [-1, 1]³ (between the distances |eye| ∓ √3), at the midpoints of S equal parts."""
    origins, directions = camera.rays()                                # (H, W, 3) each
    distance = float(camera.eye.norm())
    near, far = max(distance - math.sqrt(3), 0.0), distance + math.sqrt(3)
    t = near + (torch.arange(samples, dtype=torch.float64) + 0.5) * ((far - near) / samples)   # (S,)
    o = origins.reshape(-1, 1, 3).double()
    d = directions.reshape(-1, 1, 3).double()
    return (o + t[:, None] * d).to(dtype)


def project_occupancy(occupancy: torch.Tensor, cameras, samples: int = 64) -> torch.Tensor:
    """(B, Nv, H, W) silhouettes of B occupancy grids (B, R, R, R) in [0, 1] over [-1, 1]³: at each pixel the
    largest occupancy among ``samples`` points along its ray (trilinear between voxel centres, 0 outside the
    grid), Yan et al.'s projection. cameras: one list of Nv for every grid or B lists of Nv (each grid's own).
    Differentiable with respect to ``occupancy``; the max passes each pixel's gradient to one sample."""
    if occupancy.ndim != 4 or len(set(occupancy.shape[1:])) != 1:
        raise ValueError(f"occupancy must be (B, R, R, R), got shape {tuple(occupancy.shape)}")
    samples = _check_count(samples, "samples", minimum=2)
    B = occupancy.shape[0]
    per_shape = _per_shape_cameras(cameras, B)
    if not per_shape:
        raise ValueError("cameras must be a non-empty list of Camera (or B such lists)")
    H, W = per_shape[0][0].height, per_shape[0][0].width
    if any((c.height, c.width) != (H, W) for views in per_shape for c in views):
        raise ValueError("every camera must render one image size")
    cache = {}
    grids = []
    for views in per_shape:
        row = []
        for camera in views:
            if id(camera) not in cache:
                cache[id(camera)] = _ray_samples(camera, samples, occupancy.dtype).to(occupancy.device)
            row.append(cache[id(camera)])
        grids.append(torch.stack(row))                                 # (Nv, H W, S, 3) as (x, y, z)
    grid = torch.stack(grids)                                          # (B, Nv, H W, S, 3)
    volume = occupancy.permute(0, 3, 2, 1)[:, None]                   # (B, 1, z, y, x): grid_sample's (D, H, W)
    seen = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return seen[:, 0].amax(-1).clamp(0, 1).view(B, len(per_shape[0]), H, W)   # rounding can pass 1 by an ulp


def voxel_loss(occupancy: torch.Tensor, cameras, targets: torch.Tensor, samples: int = 64):
    """(loss, per-shape IoU loss (B,)): ``silhouette_iou_loss`` of the projections against targets (B, Nv, H, W),
    averaged over the views of each shape, then over the shapes (the mesh network's loss without its smoothness
    term, which a grid does not need)."""
    sils = project_occupancy(occupancy, cameras, samples)
    if targets.shape != sils.shape:
        raise ValueError(f"targets must be {tuple(sils.shape)} (B, Nv, H, W), got shape {tuple(targets.shape)}")
    per_shape = torch.stack([silhouette_iou_loss(s, t.to(s.dtype), reduction="mean") for s, t in zip(sils, targets)])
    return per_shape.mean(), per_shape.detach()


def train_voxel_reconstructor(train, *, settings: VoxelSettings = VoxelSettings(), steps: int = 1500,
                              batch: int = 16, views: int = 2, lr: float = 2e-3, input_views: str = "first",
                              seed: int = 0, progress: bool = False) -> tuple[VoxelReconstructor, list]:
    """(model, losses per step): Adam on ``voxel_loss`` over the ShapeSet ``train`` with ``training_batches``,
    the mesh network's batches (the same shapes, input views and supervising views at the same seed) and its
    cosine learning rate from ``lr`` to lr / 20; ``input_views`` as there ("first": view 0, "all": any view)."""
    lr = _check_real(lr, "lr", low=0, low_open=True)
    if train.images.shape[2:4] != (settings.size, settings.size):
        raise ValueError(f"the dataset's images are {tuple(train.images.shape[2:4])}, the network reads "
                         f"{settings.size} x {settings.size}")
    model = VoxelReconstructor(settings)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    steps = _check_count(steps, "steps", minimum=0)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(steps, 1), eta_min=lr / 20)
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    losses = []
    batches = training_batches(train, steps=steps, batch=batch, views=views, input_views=input_views, seed=seed)
    for idx, inputs, pick in tqdm(batches, total=steps, desc="train voxel network", disable=disable, leave=False):
        cameras = [[train.cameras[int(v)] for v in row] for row in pick]
        optimizer.zero_grad()
        occupancy = model(train.images[idx, inputs].to(model.template.dtype))
        loss, _ = voxel_loss(occupancy, cameras, train.silhouettes[idx[:, None], pick], settings.samples)
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(float(loss.detach()))
    return model.eval(), losses


def voxel_mesh(occupancy: torch.Tensor):
    """The surface of one grid (R, R, R) at occupancy 0.5 as a closed Mesh (``inverse.carve.surface_nets`` over the
    voxel centres, which span [-1 + 1/R, 1 - 1/R]), or None when no voxel is above 0.5."""
    occupancy = occupancy.detach().double()
    if occupancy.ndim != 3 or len(set(occupancy.shape)) != 1:
        raise ValueError(f"occupancy must be (R, R, R), got shape {tuple(occupancy.shape)}")
    if not bool((occupancy > 0.5).any()):
        return None
    R = occupancy.shape[0]
    return surface_nets(occupancy, radius=1 - 1 / R, level=0.5)


def save_voxel_reconstructor(model: VoxelReconstructor, path, note: str = "") -> None:
    """Write ``{"settings", "state_dict" (float32), "note"}`` to ``path``, like ``save_reconstructor``."""
    state = {k: v.detach().to(torch.float32) for k, v in model.state_dict().items()}
    torch.save({"kind": "voxel", "settings": asdict(model.settings), "state_dict": state, "note": str(note)}, path)


def load_voxel_reconstructor(path) -> VoxelReconstructor:
    """The network ``save_voxel_reconstructor`` wrote at ``path``, in eval mode (``note``: how it was made)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    data = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(data, dict) or data.get("kind") != "voxel":
        raise ValueError(f"{path} is not a voxel reconstructor checkpoint (save_voxel_reconstructor writes one)")
    model = VoxelReconstructor(VoxelSettings(**data["settings"]))
    model.load_state_dict(data["state_dict"])
    model.note = data.get("note", "")
    return model.eval()


def load_pretrained_voxel_reconstructor() -> VoxelReconstructor:
    """The voxel network shipped with the course (``course/data/voxel_reconstructor.pt``), never downloaded: made
    by ``python -m course bench learn --parts table --save-voxel course/data/voxel_reconstructor.pt`` at the
    bench's defaults (inputs from any view, seed 0, float32 weights); ``model.note`` repeats its recipe and score."""
    if not PRETRAINED.is_file():
        raise ValueError(f"the shipped checkpoint {PRETRAINED} is missing; remake it with python -m course bench "
                         "learn --parts table --save-voxel course/data/voxel_reconstructor.pt")
    return load_voxel_reconstructor(PRETRAINED)
