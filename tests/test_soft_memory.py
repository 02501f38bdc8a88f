"""Memory of soft rasterization and NMR's backward: with a small CHUNK, no tensor made on the way (forward
and backward) is anywhere near the size of the work (the candidate pairs, NMR's (pixel, edge) terms).

The size of every tensor an operator returns is recorded through a ``TorchDispatchMode``: a count of
elements, the same on every machine, not a measurement of the process's memory or of time."""
import math

import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

import course.nmr as nmr
import course.soft as soft
from course.camera import Camera
from course.mesh import Mesh
from course.models import icosphere
from course.nmr import nmr_rasterize
from course.soft import soft_rasterize


class LargestTensor(TorchDispatchMode):
    """Records the largest number of elements of any tensor an operator returns."""

    def __init__(self):
        super().__init__()
        self.largest = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        for t in tree_flatten(out)[0]:
            if isinstance(t, torch.Tensor):
                self.largest = max(self.largest, t.numel())
        return out


SIZE = 64


def scene():
    mesh = icosphere(3, dtype=torch.float64)                                # 1,280 faces
    cam = Camera.look_at((0.13, 0.21, 3.0), (0.01, -0.02, 0.0), fov_y=40.0, width=SIZE, height=SIZE,
                         dtype=torch.float64)
    return mesh, cam


def largest_tensor(render, mesh, cam):
    """The largest tensor made by ``render`` (forward and backward of a fixed loss)."""
    verts = mesh.verts.clone().requires_grad_()
    w = torch.randn(SIZE, SIZE, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    with LargestTensor() as probe:
        img = render(Mesh(verts, mesh.faces), cam)
        (img * (w if img.dim() == 3 else w[..., 0])).sum().backward()
    assert torch.isfinite(verts.grad).all() and verts.grad.abs().sum() > 0
    return probe.largest


@pytest.mark.parametrize("cull", [True, False])
def test_soft_rasterize_never_holds_all_candidates(monkeypatch, cull):
    mesh, cam = scene()
    xy, q, _, _ = soft._screen_faces(mesh.verts, mesh.faces, cam, cull)
    gamma, sigma = 1e-4, 1e-4
    s = 4.0 / (SIZE * SIZE * sigma)
    near = soft._nearness(q.double(), cam)
    radius = ((math.log(1e4) + (near.amax(1) - 1e-3).clamp(min=0) / gamma) / s).sqrt()
    candidates = soft._candidate_pairs(xy.double(), radius, SIZE, SIZE)[0].numel()
    assert candidates > 100_000                                             # the work is big
    monkeypatch.setattr(soft, "CHUNK", 2048)
    for mode in ("silhouette", "color"):
        kw = dict(mode=mode, face_colors=torch.rand(1280, 3, dtype=torch.float64)) if mode == "color" else {}
        largest = largest_tensor(lambda m, c: soft_rasterize(m, c, sigma=sigma, gamma=gamma, cull_backfaces=cull,
                                                             **kw), mesh, cam)
        # the largest are the kept pairs' (N, C) colours (a tenth of the candidates here), per-pixel maps and
        # the faces' row segments: the candidates are never all there at once
        assert largest < candidates / 3, (mode, largest, candidates)


@pytest.mark.parametrize("cull", [True, False])
def test_nmr_backward_never_holds_all_its_terms(monkeypatch, cull):
    mesh, cam = scene()
    monkeypatch.setattr(nmr, "CHUNK", 2048)
    for colours in (None, torch.rand(1280, 3, dtype=torch.float64)):
        largest = largest_tensor(lambda m, c: nmr_rasterize(m, c, face_colors=colours, cull_backfaces=cull),
                                 mesh, cam)
        # reach None: every (face, row) pair visits the whole row, faces × rows × W terms (> 200,000 here)
        assert largest <= max(4 * 2048, 4 * SIZE * SIZE, 3 * 1280 * 12), largest


def test_soft_colour_backward_holds_nothing_per_kept_pair(monkeypatch):
    """Colour mode sums the kept pairs' terms into per-pixel buffers CHUNK pairs at a time and its backward
    recomputes them chunk by chunk (``soft._ColorSums``): no tensor made during backward is as big as the kept
    pairs' (N, C) colours or the gradients of all their weights, only chunks and per-pixel maps."""
    mesh, cam = scene()
    monkeypatch.setattr(soft, "CHUNK", 2048)
    kept = {}
    color_pairs = soft._color_pairs

    def counted(*args):
        out = color_pairs(*args)
        kept["N"] = out[0].numel()
        return out
    monkeypatch.setattr(soft, "_color_pairs", counted)
    verts = mesh.verts.clone().requires_grad_()
    colours = torch.rand(1280, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64).requires_grad_()
    img = soft_rasterize(Mesh(verts, mesh.faces), cam, mode="color", sigma=1e-3, gamma=1e-4, face_colors=colours,
                         cull_backfaces=False)
    w = torch.randn(SIZE, SIZE, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    with LargestTensor() as probe:
        (img * w).sum().backward()
    assert torch.isfinite(verts.grad).all() and verts.grad.abs().sum() > 0 and colours.grad.abs().sum() > 0
    bound = max(3 * 2048, SIZE * SIZE * 3)                                  # a chunk's (CHUNK, C), an (H*W, C) map
    assert kept["N"] * 3 > 3 * bound                                        # many chunks of kept pairs
    assert probe.largest <= bound, (probe.largest, kept["N"])
