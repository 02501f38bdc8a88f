"""Learned views for multi-view recognition (lecture 13; Hamdi, Giancola and Ghanem 2021, MVTN).

A multi-view classifier recognises a 3D shape from N images of it: a small CNN, shared by the views, reads
each image to a feature vector, the N vectors are pooled (max over the views: the order of the views does
not matter) and a linear layer gives the class scores. Which views? Usually fixed ones, a circle of cameras
around the object. MVTN's idea: the images come from a *differentiable* renderer, so the classification
loss has a gradient w.r.t. the cameras too, and the views can be learned with the network::

    angles (N, 2) ─cameras─▶ soft_rasterize(mesh, cameras) (N, H, W) ─CNN─▶ (N, D) ─max─▶ (D,) ─linear─▶ scores

Four ways to choose the angles (azimuth a, elevation e; ``MVTNSettings.mode``):

* ``"fixed"``: a circle, azimuths 360°/N apart at ``elevation`` degrees, never trained;
* ``"sphere"``: N directions spread over the sphere (a Fibonacci spiral: elevations asin(1 − (2k + 1)/N),
  within ±80°, azimuths a golden angle apart), never trained: MVTN's "spherical" fixed baseline;
* ``"learned"``: N (a, e) pairs as parameters, starting on that circle, shared by every object and trained
  by backpropagation through the soft rasterizer (camera ``look_at`` → projection → soft silhouette);
* ``"predicted"``: MVTN proper, a small point network (a shared MLP on 128 points sampled on the surface,
  max-pooled) predicts each object's own offsets from the circle, bounded to ±90° in azimuth and ±60° in
  elevation; it starts at zero, so training starts on the circle.

The camera sits ``distance`` from the origin at ``(cos e sin a, sin e, cos e cos a)`` (azimuth from +z
toward +x, as ``shape_data.view_cameras``), looking at the origin, +y up; the elevation is kept inside ±80°
(``80° · tanh``) so the view never looks straight along the up vector. The images are soft silhouettes
(``soft.soft_rasterize``, σ = 3e-3, about a pixel of blur at 32 px): the gradient w.r.t. a camera comes
from how the outline moves as the camera turns, which needs the blur to reach pixels near the edges.

What to expect (``python -m course bench learn``: 100 steps of 16, seeds 0-4, the four modes): on shapes turned by
random rotations, where Hamdi et al. found learned views help most, no mode beats the fixed circle measurably
(learned +0.007 ± 0.020, predicted -0.010 ± 0.014 in accuracy, paired by seed), and the predicted views differ
between objects by only a few degrees: at this budget the view network learns one set of views for all. On
upright shapes learned and predicted views lead the circle by about two standard errors (+0.058 ± 0.028,
+0.032 ± 0.016), which five seeds do not settle. The fixed sphere of views loses to the circle in both.
Careful with "predicted": its view network reads the 3D points, so it could pass the class to the
classifier through the pose itself (turn one way for cones, another for vases); higher accuracy there does
not prove the views are better views.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import torch

from ..camera import Camera, intrinsics_from_fov, look_at
from ..mesh import Mesh
from .data import make_dataset
from ..inverse.metrics import sample_surface
from .shapes import FAMILIES
from ..soft import soft_rasterize
from ..tensors import _check_count, _check_real

__all__ = ["MVTNSettings", "MultiViewClassifier", "make_mvtn_data", "view_directions", "train_mvtn",
           "evaluate_mvtn", "plot_view_directions", "random_rotation", "MODES"]

MODES = ("fixed", "sphere", "learned", "predicted")
FIXED = ("fixed", "sphere")                # modes whose views never change: rendered once before training
MAX_ELEVATION = 80.0                     # degrees: the elevation is 80° · tanh(raw), never the pole
POINTS = 128                             # surface samples a "predicted" view network reads


@dataclass(frozen=True)
class MVTNSettings:
    """views: N cameras; mode: "fixed", "learned" or "predicted" (module docstring); classes: output scores;
    size: image side (a multiple of 8); elevation: the circle's (degrees); distance, fov_y: the cameras'
    (``shape_data.view_cameras``' defaults: every shape fits the frame); sigma: soft rasterization's; seed: of
    the initial weights."""
    views: int = 4
    mode: str = "learned"
    classes: int = 6
    size: int = 32
    elevation: float = 30.0
    distance: float = 3.2
    fov_y: float = 40.0
    sigma: float = 3e-3
    seed: int = 0


def view_directions(azimuth: torch.Tensor, elevation: torch.Tensor) -> torch.Tensor:
    """(..., 3) unit vectors from the origin toward cameras at azimuth, elevation (..., degrees each)."""
    a, e = torch.deg2rad(azimuth), torch.deg2rad(elevation)
    return torch.stack([torch.cos(e) * torch.sin(a), torch.sin(e), torch.cos(e) * torch.cos(a)], -1)


class MultiViewClassifier(torch.nn.Module):
    """Views → soft silhouettes → shared CNN → max over views → linear scores (module docstring).

    The CNN: three stride-2 3 × 3 convolutions (16, 32, 64 channels, ReLU) and a linear layer to 64 features
    per view. View parameters: ``azimuth`` (N,) degrees and ``elevation_raw`` (N,) (elevation = 80° · tanh);
    trained in mode "learned", frozen in "fixed"; in "predicted" the ``view_net`` adds per-object offsets.
    """

    def __init__(self, settings: MVTNSettings = MVTNSettings()):
        super().__init__()
        if settings.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {settings.mode!r}")
        N, size = _check_count(settings.views, "views"), _check_count(settings.size, "size")
        if size % 8:
            raise ValueError(f"size must be a multiple of 8 (three stride-2 convolutions), got {size}")
        classes = _check_count(settings.classes, "classes", minimum=2)
        elevation = _check_real(settings.elevation, "elevation", low=-MAX_ELEVATION, high=MAX_ELEVATION,
                                low_open=True, high_open=True)
        _check_real(settings.distance, "distance", low=1, low_open=True)
        self.settings = settings
        learn = settings.mode not in FIXED
        k = torch.arange(N, dtype=torch.float64)
        if settings.mode == "sphere":                                  # a Fibonacci spiral over the sphere
            azimuth = (k * 180.0 * (3 - math.sqrt(5))) % 360.0
            e = torch.rad2deg(torch.asin(1 - (2 * k + 1) / N)).clamp(-0.95 * MAX_ELEVATION, 0.95 * MAX_ELEVATION)
            raw = torch.atanh(e / MAX_ELEVATION)
        else:
            azimuth = k * (360.0 / N)
            raw = torch.full((N,), math.atanh(elevation / MAX_ELEVATION), dtype=torch.float64)
        self.azimuth = torch.nn.Parameter(azimuth.float(), requires_grad=learn)
        self.elevation_raw = torch.nn.Parameter(raw.float(), requires_grad=learn and settings.mode == "learned")
        if settings.mode == "predicted":
            self.azimuth.requires_grad_(False)                         # the circle stays; offsets are learned
        with torch.random.fork_rng(devices=[]):                        # seeded weights, global state restored
            torch.manual_seed(_check_count(settings.seed, "seed", minimum=0))
            self.cnn = torch.nn.Sequential(
                torch.nn.Conv2d(1, 16, 3, stride=2, padding=1), torch.nn.ReLU(),   # (B N, 16, H/2, W/2)
                torch.nn.Conv2d(16, 32, 3, stride=2, padding=1), torch.nn.ReLU(),  # (B N, 32, H/4, W/4)
                torch.nn.Conv2d(32, 64, 3, stride=2, padding=1), torch.nn.ReLU(),  # (B N, 64, H/8, W/8)
                torch.nn.Flatten(), torch.nn.Linear(64 * (size // 8) ** 2, 64), torch.nn.ReLU())  # (B N, 64)
            self.classifier = torch.nn.Linear(64, classes)
            self.view_net = None
            if settings.mode == "predicted":
                self.view_net = torch.nn.ModuleDict(dict(
                    point=torch.nn.Sequential(torch.nn.Linear(3, 32), torch.nn.ReLU(), torch.nn.Linear(32, 64),
                                              torch.nn.ReLU()),
                    head=torch.nn.Linear(64, 2 * N)))
                with torch.no_grad():
                    self.view_net["head"].weight.zero_(), self.view_net["head"].bias.zero_()
        self.register_buffer("K", intrinsics_from_fov(settings.fov_y, size, size, dtype=torch.float32))

    def view_angles(self, meshes=None) -> tuple[torch.Tensor, torch.Tensor]:
        """(azimuth, elevation) in degrees: (N,) each, or (B, N) for the list of B ``meshes`` in mode
        "predicted" (the circle plus each object's offsets)."""
        azimuth = self.azimuth
        elevation_raw = self.elevation_raw
        if self.view_net is not None and meshes is not None:
            points = torch.stack([sample_surface(m, POINTS, torch.Generator().manual_seed(0))[0].float()
                                  for m in meshes])                    # (B, P, 3)
            feature = self.view_net["point"](points).max(1).values    # (B, 64): PointNet's max pooling
            offset = torch.tanh(self.view_net["head"](feature)).view(len(meshes), 2, -1)  # (B, 2, N) in (-1, 1)
            azimuth = azimuth + 90.0 * offset[:, 0]                    # (B, N) ±90°
            elevation_raw = elevation_raw + offset[:, 1]               # about ±60° near the circle's 30°
        return azimuth, MAX_ELEVATION * torch.tanh(elevation_raw)

    def cameras(self, azimuth: torch.Tensor, elevation: torch.Tensor) -> list:
        """N ``Camera`` at these (N,) angles (degrees), differentiable w.r.t. them (through ``look_at``)."""
        s = self.settings
        eyes = s.distance * view_directions(azimuth, elevation)        # (N, 3)
        cameras = []
        for eye in eyes:
            R, t = look_at(eye, eye.new_zeros(3), eye.new_tensor([0.0, 1.0, 0.0]))
            cameras.append(Camera(self.K, R, t, s.size, s.size, near=0.1, far=100.0))
        return cameras

    def render(self, meshes) -> torch.Tensor:
        """(B, N, H, W) soft silhouettes of the B meshes from the current views (one camera-batch call each)."""
        azimuth, elevation = self.view_angles(meshes)
        shared = azimuth.ndim == 1
        cams = self.cameras(azimuth, elevation) if shared else None
        images = []
        for b, mesh in enumerate(meshes):
            views = cams if shared else self.cameras(azimuth[b], elevation[b])
            images.append(soft_rasterize(mesh, views, mode="silhouette", sigma=self.settings.sigma))
        return torch.stack(images)

    def classify(self, images: torch.Tensor) -> torch.Tensor:
        """(B, classes) scores from (B, N, H, W) view images: the shared CNN per view, max over the views."""
        if images.ndim != 4 or images.shape[1:] != (self.settings.views, self.settings.size, self.settings.size):
            raise ValueError(f"images must be (B, {self.settings.views}, {self.settings.size}, "
                             f"{self.settings.size}), got shape {tuple(images.shape)}")
        B, N, H, W = images.shape
        features = self.cnn(images.reshape(B * N, 1, H, W)).view(B, N, -1)  # (B, N, 64)
        return self.classifier(features.max(1).values)                 # (B, classes)

    def forward(self, meshes) -> torch.Tensor:
        """(B, classes) scores of a list of B meshes."""
        if isinstance(meshes, torch.Tensor) or not meshes:
            raise ValueError("meshes must be a non-empty list of Mesh")
        return self.classify(self.render(meshes))


def make_mvtn_data(n_train: int, n_test: int, *, families=None, seed: int = 0, rotate: bool = False,
                   progress: bool = False):
    """(train, test) ``shape_data.ShapeSet``s of ``families`` (default: the six training families, the torus
    held out as everywhere in lecture 13), float32, different shapes (splits "train" and "test"). Only the
    meshes and labels are used; the classifier renders its own views. rotate: turn every mesh by its own
    uniformly random rotation (``random_rotation`` seeded by the shape's seed), so the shapes no longer stand
    upright: the case where Hamdi et al. found learned views help most."""
    families = tuple(f for f in FAMILIES if f != "torus") if families is None else families
    common = dict(families=families, seed=seed, views=1, size=8, dtype=torch.float32, progress=progress)
    sets = make_dataset(n_train, split="train", **common), make_dataset(n_test, split="test", **common)
    if not rotate:
        return sets
    from dataclasses import replace
    turned = []
    for data in sets:
        meshes = [Mesh(m.verts @ random_rotation(int(s)).to(m.verts.dtype).T, m.faces)
                  for m, s in zip(data.meshes, data.seeds)]
        turned.append(replace(data, meshes=meshes))                    # the images and silhouettes are unused
    return tuple(turned)


def random_rotation(seed: int) -> torch.Tensor:
    """(3, 3) float64 a rotation drawn uniformly (Haar measure) with ``seed``: a unit quaternion from four
    normal draws (Shoemake), turned into its matrix."""
    q = torch.randn(4, generator=torch.Generator().manual_seed(int(seed) % (2 ** 63)), dtype=torch.float64)
    w, x, y, z = (q / q.norm()).tolist()
    return torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]], dtype=torch.float64)


def train_mvtn(train, *, settings: MVTNSettings = MVTNSettings(), steps: int = 150, batch: int = 24,
               lr: float = 3e-3, view_lr: float = 0.5, seed: int = 0,
               progress: bool = False) -> tuple[MultiViewClassifier, list]:
    """(model, losses): Adam on the cross-entropy of the ShapeSet ``train``'s labels, ``steps`` batches of
    ``batch`` shapes (shuffled epochs, seeded by ``seed``). In mode "learned" the angles learn at their own
    rate, about ``view_lr`` degrees a step at most (Adam's step is about its rate whatever the gradient's
    scale); ``lr`` for every other weight (the view network's too). In modes "fixed" and "sphere" the
    silhouettes are rendered once, before training."""
    steps, batch = _check_count(steps, "steps", minimum=0), _check_count(batch, "batch")
    lr, view_lr = _check_real(lr, "lr", low=0, low_open=True), _check_real(view_lr, "view_lr", low=0)
    if settings.classes != len(train.families):
        raise ValueError(f"settings.classes is {settings.classes} but the data has {len(train.families)} families")
    model = MultiViewClassifier(settings)
    others = [p for n, p in model.named_parameters() if n not in ("azimuth", "elevation_raw")]
    groups = [dict(params=others, lr=lr)]
    if settings.mode == "learned":                                     # elevation_raw is in tanh units: near 30°
        groups += [dict(params=[model.azimuth], lr=view_lr),          # one unit is about 60°
                   dict(params=[model.elevation_raw], lr=view_lr / 60)]
    optimizer = torch.optim.Adam(groups)
    fixed = None
    if settings.mode in FIXED:
        with torch.no_grad():
            fixed = model.render(train.meshes)                         # (N_shapes, N, H, W) once
    g = torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0))
    order, losses = torch.empty(0, dtype=torch.long), []
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    bar = tqdm(range(steps), desc=f"train MVTN ({settings.mode})", disable=disable, leave=False)
    for _ in bar:
        while order.numel() < batch:
            order = torch.cat([order, torch.randperm(len(train), generator=g)])
        idx, order = order[:batch], order[batch:]
        optimizer.zero_grad()
        scores = model.classify(fixed[idx]) if fixed is not None else model([train.meshes[int(i)] for i in idx])
        loss = torch.nn.functional.cross_entropy(scores, train.labels[idx])
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
        bar.set_postfix(loss=f"{losses[-1]:.3f}", refresh=False)
    return model.eval(), losses


def evaluate_mvtn(model: MultiViewClassifier, test, batch: int = 32) -> float:
    """The fraction of the ShapeSet ``test`` classified right."""
    right = 0
    with torch.no_grad():
        for lo in range(0, len(test), batch):
            scores = model(test.meshes[lo:lo + batch])
            right += int((scores.argmax(1) == test.labels[lo:lo + batch]).sum())
    return right / len(test)


def plot_view_directions(angles: dict, path=None):
    """A 3D scatter of view directions on the unit sphere: ``angles`` maps a label to (azimuth, elevation)
    tensors in degrees ((N,) or (B, N); e.g. ``model.view_angles()``), one colour per label. Returns the figure.
    The y axis (up, the shapes' axis) is drawn vertical."""
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(4.8, 4.8))
    ax = fig.add_subplot(projection="3d")
    u, v = torch.meshgrid(torch.linspace(0, 2 * math.pi, 25), torch.linspace(-math.pi / 2, math.pi / 2, 13),
                          indexing="ij")
    ax.plot_wireframe(torch.cos(v) * torch.sin(u), torch.cos(v) * torch.cos(u), torch.sin(v), color="0.85",
                      linewidth=0.5)
    for i, (label, (azimuth, elevation)) in enumerate(angles.items()):
        d = view_directions(torch.as_tensor(azimuth).detach().float(),
                            torch.as_tensor(elevation).detach().float()).reshape(-1, 3)
        ax.scatter(d[:, 0], d[:, 2], d[:, 1], color=f"C{i}", s=30, label=label, depthshade=False)  # y drawn up
    ax.set_xlabel("x"), ax.set_ylabel("z"), ax.set_zlabel("y (up)")
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):                       # the unit sphere: -1, 0, 1 say enough
        axis.set_ticks([-1.0, 0.0, 1.0])
    ax.set_box_aspect((1, 1, 1))
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig
