"""Single-image mesh reconstruction through the renderer (lecture 13; Kato, Ushiku and Harada 2018, section 4.2).

A small convolutional encoder reads one image of a shape and predicts how a sphere deforms into it: an
offset per vertex of an icosphere, and a per-axis scale and a translation of the whole. Nothing 3D
supervises it. Each predicted mesh is rendered by soft rasterization (``soft.soft_rasterize``, a shape's
views in one call: a camera batch; the shapes of a batch in a loop) from two or more known views, and compared with the shape's silhouettes there by
Kato et al.'s IoU loss, plus their smoothness loss so the sphere deforms without folding::

    image (H, W, 3) ─encoder─▶ code (64,) ─heads─▶ verts = (sphere + offsets) · scale + translation (V, 3)
    verts ─soft_rasterize(views)─▶ (Nv, H, W) ─silhouette_iou_loss(·, targets)─▶ + λ smoothness_loss

The views and the data come from ``course.learning.data`` (the image of one view in, silhouettes of other views out).
The soft silhouette needs a blur of about a pixel to pass gradients from pixels the mesh misses: σ = 3e-3 in
the NDC units of ``soft_rasterize`` is σ_px = σ W² / 4 ≈ 0.8 px² at W = 32; ``train_reconstructor`` then
sharpens it tenfold over training, because a blurred outline is wider than the mesh's and a network fitted to
it learns meshes too small (at 32 px about a pixel all round: a third of the volume of a capsule).

* ``train_reconstructor(train, ...)``: seeded Adam, a cosine learning rate, a random pair of the dataset's
  views per shape and step as targets, σ shrinking geometrically; a tqdm bar with ``progress=True``.
* ``training_batches``: which shapes, which input view and which supervising views each step takes, the same for
  the voxel network (``voxels``): view 0 of every shape as the input ("first"), or any of its views ("all", as
  Kato et al.); the supervising views are never the input.
* ``evaluate_reconstruction(model, train, test)``: per family, the voxel IoU at 32³ (``data.voxelize``) and the
  Chamfer distance of the network's mesh given view 0, of *retrieval* (the training shape with the nearest view-0
  image, as it is) and of the untrained *sphere*: a quick look. Kato et al.'s whole Table 1 (the voxel network,
  retrieval over every view, clustering, the oracle nearest shape, the F-score, both input protocols) is
  ``learning.table``, run by ``python -m course bench learn``.
* ``save_reconstructor`` / ``load_reconstructor`` and ``load_pretrained_reconstructor()``: the network the
  bench's defaults train on inputs from any view, shipped as ``course/data/reconstructor.pt`` (float32, about 0.5 MB; never
  downloaded).
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from ..inverse.losses import interior_edges, silhouette_iou_loss
from ..mesh import Mesh
from ..models import icosphere
from .data import voxel_iou, voxelize
from ..inverse.metrics import chamfer_distance
from ..soft import soft_rasterize
from ..tensors import _check_count, _check_finite, _check_real, as_tensor

__all__ = ["ReconstructionSettings", "MeshReconstructor", "network_images", "reconstruction_loss",
           "batched_smoothness", "train_step", "train_reconstructor", "retrieve", "shape_scores",
           "evaluate_reconstruction", "save_reconstructor", "load_reconstructor", "load_pretrained_reconstructor",
           "PRETRAINED"]

PRETRAINED = Path(__file__).parents[1] / "data" / "reconstructor.pt"


@dataclass(frozen=True)
class ReconstructionSettings:
    """The network and loss settings. size: input image side (a multiple of 8); subdivisions: of the icosphere
    template (2: 162 vertices, 320 faces); radius: the template's; code: the length of the code between encoder
    and heads (64 keeps the whole network near 120,000 numbers, under 0.5 MB in float32); sigma: soft
    rasterization's sharpness (NDC); smoothness: the weight λ of the smoothness loss; seed: of the initial
    weights."""
    size: int = 32
    subdivisions: int = 2
    radius: float = 0.6
    code: int = 64
    sigma: float = 3e-3
    smoothness: float = 1e-3
    seed: int = 0


class MeshReconstructor(torch.nn.Module):
    """An encoder from one image to the vertices of a deformed icosphere. Faces are the template's (``faces``).

    Three stride-2 3 × 3 convolutions (16, 32, 64 channels, ReLU) take the (B, H, W, 3) images to (B, 64, H/8,
    W/8), a linear layer to a code (``settings.code`` long, ReLU), then three linear heads: offsets (V × 3),
    log-scale (3) and translation (3). The heads start at zero (offsets nearly so), so every prediction starts
    as the template sphere: the loss's first gradients then come from the silhouettes, not from a random mesh.
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
        V, code = template.num_verts, _check_count(settings.code, "code")
        with torch.random.fork_rng(devices=[]):                        # seeded weights, global state restored
            torch.manual_seed(_check_count(settings.seed, "seed", minimum=0))
            self.encoder = image_encoder(size, code)
            self.offsets = torch.nn.Linear(code, V * 3)
            self.log_scale = torch.nn.Linear(code, 3)
            self.translation = torch.nn.Linear(code, 3)
        with torch.no_grad():
            self.offsets.weight.mul_(1e-2), self.offsets.bias.zero_()
            for head in (self.log_scale, self.translation):
                head.weight.zero_(), head.bias.zero_()

    def forward(self, images) -> torch.Tensor:
        """(B, V, 3) predicted vertices (world space) from images (B, H, W, 3) in [0, 1], H = W = size: a tensor or
        numpy array of any float dtype (run in the network's), or uint8 (0-255, divided by 255)."""
        images = network_images(images, self.settings.size, self.template.dtype)
        B = images.shape[0]
        code = self.encoder(images.permute(0, 3, 1, 2))               # (B, code) from (B, 3, H, W)
        offsets = self.offsets(code).view(B, -1, 3)                   # (B, V, 3)
        scale = torch.exp(self.log_scale(code))[:, None]              # (B, 1, 3) per axis, positive
        return (self.template + offsets) * scale + self.translation(code)[:, None]


def network_images(images, size: int, dtype: torch.dtype, name: str = "images") -> torch.Tensor:
    """``images`` as the networks read them: (B, size, size, 3) of ``dtype``, colours in [0, 1]. Accepts a tensor
    or numpy array of any real dtype (uint8: 0-255, divided by 255). Raises ValueError naming what is wrong: the
    shape, NaN or inf, or values outside [0, 1] (a network fed 1e30 would answer with vertices at 1e27)."""
    integer_255 = (isinstance(images, torch.Tensor) and images.dtype == torch.uint8) or (
        getattr(images, "dtype", None) is not None and str(getattr(images, "dtype")) == "uint8")
    images = as_tensor(images, name=name)
    if integer_255:
        images = images / 255.0
    if images.ndim != 4 or images.shape[1:] != (size, size, 3):
        raise ValueError(f"{name} must be (B, {size}, {size}, 3), got shape {tuple(images.shape)}")
    if images.shape[0] == 0:
        raise ValueError(f"{name} is empty (B = 0)")
    _check_finite(images, name)
    low, high = float(images.min()), float(images.max())
    if low < -1e-6 or high > 1 + 1e-6:
        raise ValueError(f"{name} must hold colours in [0, 1] (uint8 images 0-255 are divided by 255), got values "
                         f"from {low:.3g} to {high:.3g}")
    return images.to(dtype)


def image_encoder(size: int, code: int) -> torch.nn.Sequential:
    """(B, 3, H, W) images, H = W = ``size`` (a multiple of 8) → (B, ``code``): three stride-2 3 × 3 convolutions
    (16, 32, 64 channels, ReLU), then a linear layer and a ReLU. The mesh and the voxel networks read their
    images with the same encoder, so a difference between them is their decoders'."""
    return torch.nn.Sequential(
        torch.nn.Conv2d(3, 16, 3, stride=2, padding=1), torch.nn.ReLU(),            # (B, 16, H/2, W/2)
        torch.nn.Conv2d(16, 32, 3, stride=2, padding=1), torch.nn.ReLU(),           # (B, 32, H/4, W/4)
        torch.nn.Conv2d(32, 64, 3, stride=2, padding=1), torch.nn.ReLU(),           # (B, 64, H/8, W/8)
        torch.nn.Flatten(), torch.nn.Linear(64 * (size // 8) ** 2, code), torch.nn.ReLU())  # (B, code)


def reconstruction_loss(verts: torch.Tensor, faces: torch.Tensor, cameras, targets: torch.Tensor, *,
                        sigma: float = 3e-3, smoothness: float = 1e-3) -> tuple[torch.Tensor, torch.Tensor]:
    """(loss, per-shape IoU loss (B,)): the mean over the B shapes of the silhouette IoU loss averaged over the
    Nv views plus ``smoothness`` × ``smoothness_loss``.

    verts: (B, V, 3) predicted vertices; faces: (F, 3); cameras: list of Nv Camera (one image size H × W), the
    same views for every shape, or a list of B such lists, shape b's own views (``train_reconstructor`` draws
    a random pair per shape); targets: (B, Nv, H, W) silhouettes in [0, 1]. Each shape's views are one
    ``soft_rasterize`` call (back faces kept: a deforming sphere may fold, and its silhouette should still
    count every face).
    """
    per_shape = _per_shape_cameras(cameras, verts.shape[0] if verts.ndim == 3 else -1)
    Nv = len(per_shape[0]) if per_shape else len(cameras)
    if verts.ndim != 3 or targets.ndim != 4 or targets.shape[:2] != (verts.shape[0], Nv):
        raise ValueError(f"need verts (B, V, 3) and targets (B, Nv={Nv}, H, W), got "
                         f"{tuple(verts.shape)} and {tuple(targets.shape)}")
    iou_losses = []
    for b in range(verts.shape[0]):
        mesh = Mesh(verts[b], faces)
        sils = soft_rasterize(mesh, per_shape[b], mode="silhouette", sigma=sigma, cull_backfaces=False)  # (Nv,H,W)
        iou_losses.append(silhouette_iou_loss(sils, targets[b].to(sils.dtype), reduction="mean"))
    iou_losses = torch.stack(iou_losses)                              # (B,)
    return iou_losses.mean() + smoothness * batched_smoothness(verts, faces).mean(), iou_losses.detach()


def batched_smoothness(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B,) ``losses.smoothness_loss`` of each of B meshes sharing ``faces`` (F, 3), verts (B, V, 3): the edges
    between faces found once for the batch (``interior_edges``, a sort of all 3F sides) instead of once a shape."""
    _, pairs = interior_edges(faces)                                   # (E, 2) the two faces of each edge
    tri = verts[:, faces]                                              # (B, F, 3, 3)
    cross = torch.linalg.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0], dim=-1)  # (B, F, 3)
    length = cross.norm(dim=-1, keepdim=True)
    normals = cross / torch.where(length > 0, length, torch.ones_like(length))  # unit, or 0 for a degenerate face
    cos_normals = (normals[:, pairs[:, 0]] * normals[:, pairs[:, 1]]).sum(-1)   # (B, E) n₁·n₂
    return ((1 - cos_normals) ** 2).sum(-1)


def _per_shape_cameras(cameras, B: int) -> list:
    """B lists of cameras from one shared list or B lists (checked: each list non-empty, all one length)."""
    cameras = list(cameras)
    if cameras and all(isinstance(c, (list, tuple)) for c in cameras):
        if len(cameras) != B or len({len(c) for c in cameras}) != 1 or not cameras[0]:
            raise ValueError(f"per-shape cameras must be B={B} lists of one length, got {len(cameras)} lists")
        return [list(c) for c in cameras]
    return [cameras] * max(B, 0) if cameras else []


def train_step(model: MeshReconstructor, optimizer: torch.optim.Optimizer, images: torch.Tensor,
               silhouettes: torch.Tensor, cameras, sigma: float | None = None) -> float:
    """One optimisation step on a batch: images (B, H, W, 3) in, silhouettes (B, Nv, H, W) of ``cameras`` (one
    list for all, or B lists: ``reconstruction_loss``) as targets; sigma: soft rasterization's (default the
    model's settings.sigma). Returns the loss before the step."""
    optimizer.zero_grad()
    verts = model(images)
    sigma = model.settings.sigma if sigma is None else sigma
    loss, _ = reconstruction_loss(verts, model.faces, cameras, silhouettes, sigma=sigma,
                                  smoothness=model.settings.smoothness)
    loss.backward()
    optimizer.step()
    return float(loss.detach())


# ---- training ----------------------------------------------------------------------------------------------

def train_reconstructor(train, *, settings: ReconstructionSettings = ReconstructionSettings(), steps: int = 1500,
                        batch: int = 16, views: int = 2, lr: float = 2e-3, final_sigma: float | None = None,
                        seed: int = 0, model=None, input_views: str = "first",
                        progress: bool = False) -> tuple[MeshReconstructor, list]:
    """(model, losses per step): Adam on ``reconstruction_loss`` over the ShapeSet ``train``; the input image is
    view 0 of each shape (``input_views="first"``) or any of its views ("all": ``training_batches``).

    Each step draws ``batch`` shapes (an epoch's shuffled order, then the next) and for each shape ``views``
    distinct views of the dataset's Nv at random, its own pair: a network that sees all views of every shape two
    at a time learns more of each shape's depth than one that always sees the same two, at the cost of two.
    The learning rate follows a cosine from ``lr`` down to lr / 20 over the steps (large steps while the
    sphere finds the families' outlines, small ones for the details). The blur σ of the soft silhouettes
    shrinks geometrically from ``settings.sigma`` to ``final_sigma`` (default a tenth of it): a blurred
    silhouette spreads past the mesh's outline (every face near the edge, front and back, adds a little
    probability outside it), so a network trained only at a pixel's blur learns meshes about a pixel too
    small, while a sharp silhouette from the start passes gradients from too few pixels. Seeded by ``seed``
    (the order and the views; the weights by ``settings.seed``) through a private generator: torch's global
    state is untouched.
    model: continue training this one (its own settings then apply). progress: a tqdm bar with the loss.
    """
    steps = _check_count(steps, "steps", minimum=0)
    lr = _check_real(lr, "lr", low=0, low_open=True)
    if train.images.shape[2:4] != (settings.size, settings.size) and model is None:
        raise ValueError(f"the dataset's images are {tuple(train.images.shape[2:4])}, the network reads "
                         f"{settings.size} x {settings.size}")
    model = model if model is not None else MeshReconstructor(settings)
    sigma0 = model.settings.sigma
    final_sigma = sigma0 / 10 if final_sigma is None else _check_real(final_sigma, "final_sigma", low=0,
                                                                       low_open=True)
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(steps, 1), eta_min=lr / 20)
    losses = []
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    batches = training_batches(train, steps=steps, batch=batch, views=views, input_views=input_views, seed=seed)
    bar = tqdm(batches, total=steps, desc="train reconstructor", disable=disable, leave=False)
    for step, (idx, inputs, pick) in enumerate(bar):
        sigma = sigma0 * (final_sigma / sigma0) ** (step / max(steps - 1, 1))  # geometric, σ0 → final
        cameras = [[train.cameras[int(v)] for v in row] for row in pick]
        targets = train.silhouettes[idx[:, None], pick]                # (B, views, H, W)
        losses.append(train_step(model, optimizer, train.images[idx, inputs], targets, cameras, sigma))
        schedule.step()
        bar.set_postfix(loss=f"{losses[-1]:.3f}", refresh=False)
    return model.eval(), losses


INPUT_VIEWS = ("first", "all")


def training_batches(train, *, steps: int, batch: int, views: int, input_views: str = "first", seed: int = 0):
    """An iterator over ``steps`` batches (idx (B,), inputs (B,), pick (B, views)): which shapes, which of their views is the
    input image and which views' silhouettes supervise, drawn by a private generator seeded by ``seed``.

    Shapes come in the shuffled order of one epoch after another. input_views "first": the input is view 0
    of every shape, the supervising views ``views`` distinct views of the dataset's Nv (view 0 among them or
    not); "all": ``views + 1`` distinct views, the first the input and the others the supervision, so every
    view serves as an input and a shape is never supervised by the view it was shown from.
    """
    steps, batch = _check_count(steps, "steps", minimum=0), _check_count(batch, "batch")
    if input_views not in INPUT_VIEWS:
        raise ValueError(f"input_views must be one of {INPUT_VIEWS}, got {input_views!r}")
    N, Nv = train.silhouettes.shape[:2]
    views = _check_count(views, "views")
    drawn = views + (input_views == "all")
    if drawn > Nv:
        raise ValueError(f"views must be at most the dataset's {Nv - (input_views == 'all')} views "
                         f"(input_views={input_views!r}), got {views}")
    return _batches(N, Nv, steps, batch, drawn, input_views == "first",
                    torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0)))


def _batches(N, Nv, steps, batch, drawn, first, g):
    order = torch.empty(0, dtype=torch.long)
    for _ in range(steps):
        while order.numel() < batch:                                   # the next shapes of shuffled epochs
            order = torch.cat([order, torch.randperm(N, generator=g)])
        idx, order = order[:batch], order[batch:]
        pick = torch.rand(batch, Nv, generator=g).argsort(1)[:, :drawn]  # (B, drawn) distinct views per shape
        if first:
            yield idx, torch.zeros(batch, dtype=torch.long), pick
        else:
            yield idx, pick[:, 0], pick[:, 1:]


# ---- evaluation --------------------------------------------------------------------------------------------

def retrieve(train, images: torch.Tensor) -> torch.Tensor:
    """(B,) int64 the index of the training shape whose view-0 image is nearest (sum of squared differences)
    to each of images (B, H, W, 3): the retrieval baseline, a lookup with no 3D reasoning at all
    (``table.retrieve_shape`` with every input from view 0)."""
    from .table import retrieve_shape
    return retrieve_shape(train, images, "first")


def shape_scores(pred, target, *, resolution: int = 32, samples: int = 2000, target_voxels=None) -> dict:
    """``{"iou", "chamfer"}`` of one predicted Mesh against its target Mesh: the IoU of their ``voxelize``
    occupancy at ``resolution``³ over [-1, 1]³ and ``shape_metrics.chamfer_distance`` with ``samples`` points a
    side (a fraction of the target's bounding-box diagonal). target_voxels: the target's grid, if at hand."""
    target_voxels = voxelize(target, resolution) if target_voxels is None else target_voxels
    pred = Mesh(pred.verts.detach().double(), pred.faces)
    return dict(iou=voxel_iou(voxelize(pred, resolution), target_voxels),
                chamfer=chamfer_distance(pred, target, samples=samples))


def evaluate_reconstruction(model: MeshReconstructor, train, test, *, resolution: int = 32, samples: int = 2000,
                            split: str = "test", progress: bool = False) -> list:
    """Rows, one per family of ``test`` and a last one ("mean", over all its shapes): the mean voxel IoU
    (``resolution``³) and Chamfer distance (``samples`` points a side) of three predictions from view 0:

    * ``network``: the model's mesh;
    * ``retrieval``: the training shape whose view-0 image is nearest (``retrieve``), as it is;
    * ``sphere``: the untrained network's output, the template sphere, the same for every shape.

    Row keys: split, family, n, iou_network, iou_retrieval, iou_sphere, chamfer_network, chamfer_retrieval,
    chamfer_sphere. Pass the held-out families as ``test`` (and another ``split`` name) for the generalisation
    row: retrieval can only answer with a training family there, and still beats the network on the torus.
    """
    from tqdm.auto import tqdm
    with torch.no_grad():
        verts = model(test.images[:, 0].to(model.template.dtype))     # (N, V, 3)
    nearest = retrieve(train, test.images[:, 0])
    sphere = Mesh(model.template, model.faces)
    sphere_voxels, retrieved_voxels = voxelize(sphere, resolution), {}
    scores = {"network": [], "retrieval": [], "sphere": []}
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    for n in tqdm(range(len(test)), desc=f"evaluate {split}", disable=disable, leave=False):
        target = test.meshes[n]
        voxels = voxelize(target, resolution)
        common = dict(resolution=resolution, samples=samples, target_voxels=voxels)
        scores["network"].append(shape_scores(Mesh(verts[n], model.faces), target, **common))
        k = int(nearest[n])
        if k not in retrieved_voxels:
            retrieved_voxels[k] = voxelize(train.meshes[k], resolution)
        for method, mesh, grid in (("retrieval", train.meshes[k], retrieved_voxels[k]),
                                   ("sphere", sphere, sphere_voxels)):
            scores[method].append(dict(iou=voxel_iou(grid, voxels),
                                       chamfer=chamfer_distance(mesh, target, samples=samples)))
    rows = []
    groups = [(f, (test.labels == k).nonzero()[:, 0].tolist()) for k, f in enumerate(test.families)]
    for family, members in groups + [("mean", list(range(len(test))))]:
        row = dict(split=split, family=family, n=len(members))
        for metric in ("iou", "chamfer"):
            for method, values in scores.items():
                row[f"{metric}_{method}"] = sum(values[i][metric] for i in members) / max(len(members), 1)
        rows.append(row)
    return rows


# ---- checkpoints -------------------------------------------------------------------------------------------

def save_reconstructor(model: MeshReconstructor, path, note: str = "") -> None:
    """Write ``{"settings", "state_dict" (float32), "note"}`` to ``path`` (``torch.save``); ``note`` says how the
    weights were made. The template and faces are buffers: they travel with the weights."""
    state = {k: v.detach().to(torch.float32) if v.is_floating_point() else v for k, v in model.state_dict().items()}
    torch.save({"settings": asdict(model.settings), "state_dict": state, "note": str(note)}, path)


def load_reconstructor(path) -> MeshReconstructor:
    """The network saved by ``save_reconstructor`` at ``path``, in eval mode (``note`` attribute: how it was
    made). Loads tensors and plain values only (``weights_only``); raises ValueError for another file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    data = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(data, dict) or not {"settings", "state_dict"} <= set(data):
        raise ValueError(f"{path} is not a reconstructor checkpoint (save_reconstructor writes one)")
    model = MeshReconstructor(ReconstructionSettings(**data["settings"]))
    model.load_state_dict(data["state_dict"])
    model.note = data.get("note", "")
    return model.eval()


def load_pretrained_reconstructor() -> MeshReconstructor:
    """The network shipped with the course (``course/data/reconstructor.pt``), never downloaded: made by
    ``python -m course bench learn --save course/data/reconstructor.pt`` at the bench's defaults (inputs from
    any of 24 views, seed 0, float32 weights), so anyone can remake it; ``model.note`` repeats its recipe and its scores.
    Use it to look at reconstructions without the minutes of training."""
    if not PRETRAINED.is_file():
        raise ValueError(f"the shipped checkpoint {PRETRAINED} is missing; remake it with "
                         "python -m course bench learn --save course/data/reconstructor.pt")
    return load_reconstructor(PRETRAINED)
