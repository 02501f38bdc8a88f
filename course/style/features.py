"""Texture statistics without a pretrained network, and the style images to match (lecture 11).

Gatys, Ecker and Bethge (2016) describe the *style* of an image by the Gram matrices of a convolutional
network's feature maps: which features fire together, averaged over every position, so the arrangement is
forgotten and the texture kept. Their network is a VGG trained on ImageNet; none can be downloaded here.
Ustyuzhaninov, Brendel, Gatys and Bethge (ICLR 2017) found that a network of many *random* filters at several
sizes, one layer deep, carries texture statistics well enough to synthesise textures. ``RandomFeatures`` is
that network, seeded: random filters of several sizes applied to an image pyramid, a ReLU, and the Gram
matrix of every (scale, filter size) block. A pretrained VGG adds what random filters lack: features tuned
to natural images (edges at many orientations, object parts), hence cleaner textures and a notion of
content; these statistics stay closer to colours, frequencies and orientations.

* ``gram_matrix(features)``: (C, C) feature co-activations, averaged over the H W positions;
* ``style_loss(grams, target_grams)``: the summed squared difference, each block relative to its target's
  size, so every scale counts alike;
* ``synthesize_texture(style, size, steps, seed)``: a texture of any size with the style's statistics, by
  gradient descent on the pixels (Gatys et al. 2015), the first thing to check before a mesh is textured;
* style images made from nothing: ``stripes``, ``dots``, ``marble``.
"""
from __future__ import annotations

import math
import os

import torch

from ..tensors import _check_count, _check_real, as_tensor

__all__ = ["RandomFeatures", "gram_matrix", "style_loss", "synthesize_texture", "stripes", "dots", "marble"]


def _check_image(image, name="image"):
    """(H, W, 3) float image → (1, 3, H, W)."""
    x = as_tensor(image, name=name)
    if x.dim() != 3 or x.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {tuple(x.shape)}")
    if min(x.shape[:2]) < 4:
        raise ValueError(f"{name} must be at least 4 x 4 pixels, got {tuple(x.shape[:2])}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{name} contains NaN or inf")
    return x.permute(2, 0, 1)[None]


def gram_matrix(features: torch.Tensor) -> torch.Tensor:
    """The Gram matrix of feature maps (C, H, W) or (1, C, H, W): ``G_ij = Σ_p F_i(p) F_j(p) / (H W)``, (C, C).

    Averaging over the positions (rather than summing) makes it independent of the image size, so a small
    style image and a large synthesised texture compare directly."""
    f = features[0] if features.dim() == 4 else features
    if f.dim() != 3:
        raise ValueError(f"features must have shape (C, H, W) or (1, C, H, W), got {tuple(features.shape)}")
    f = f.reshape(f.shape[0], -1)
    return f @ f.T / f.shape[1]


def style_loss(grams, target_grams) -> torch.Tensor:
    """``Σ_l ‖G_l - T_l‖² / ‖T_l‖²`` over the blocks l: each block's error relative to its target's size, so a
    scale whose features are weak counts as much as a strong one. grams, target_grams: lists of (C, C)."""
    if len(grams) != len(target_grams) or not grams:
        raise ValueError(f"grams and target_grams must be equally long, non-empty lists, got {len(grams)} and "
                         f"{len(target_grams)}")
    total = 0.0
    for g, t in zip(grams, target_grams):
        total = total + ((g - t) ** 2).sum() / (t ** 2).sum().clamp_min(1e-12)
    return total


class RandomFeatures(torch.nn.Module):
    """A one-layer network of random filters at several sizes over an image pyramid (Ustyuzhaninov et al.).

    sizes: filter sizes (odd); channels: filters per size; scales: pyramid levels (each half the previous,
    by 2 x 2 averaging); seed: the filters' seed. Filters are zero-mean (a filter with a mean responds to
    brightness alone) and scaled to unit norm. ``forward(image)`` with image (H, W, 3) in [0, 1] returns the
    list of Gram matrices: the colour block (4, 4), then one per (scale, size), len(scales) * len(sizes)
    blocks of (channels, channels).
    A first block, the Gram matrix of (R, G, B, 1), holds the mean colour and its covariance, which zero-mean
    filters cannot see. The filters are buffers, not parameters: nothing here is trained.
    """

    def __init__(self, sizes=(3, 5, 9), channels: int = 48, scales: int = 3, seed: int = 0, dtype=torch.float32):
        super().__init__()
        sizes = tuple(_check_count(s, "filter size") for s in sizes)
        if not sizes or any(s % 2 == 0 for s in sizes):
            raise ValueError(f"sizes must be odd filter sizes, got {sizes}")
        self.channels = _check_count(channels, "channels")
        self.scales = _check_count(scales, "scales")
        self.sizes = sizes
        g = torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0))
        for s in sizes:
            w = torch.randn(self.channels, 3, s, s, generator=g, dtype=torch.float64)
            w = w - w.mean(dim=(1, 2, 3), keepdim=True)
            w = w / w.flatten(1).norm(dim=1)[:, None, None, None]
            self.register_buffer(f"filters_{s}", w.to(dtype))

    def features(self, image) -> list:
        """The filter responses (1, channels, H_l, W_l) of every (scale, size) block, scale by scale: the
        maps whose Gram matrices ``forward`` returns (after the colour block)."""
        return self._maps(self._input(image))

    def _input(self, image):
        """image (H, W, 3), checked, as (1, 3, H, W) in the filters' dtype."""
        return _check_image(image).to(getattr(self, f"filters_{self.sizes[0]}").dtype)

    def _maps(self, x):
        maps = []
        for level in range(self.scales):
            if level:
                if min(x.shape[-2:]) < 2 * (max(self.sizes) // 2 + 1):     # the next level wraps its filters
                    raise ValueError(f"the image is too small for {self.scales} scales of filters up to "
                                     f"{max(self.sizes)} pixels")
                x = torch.nn.functional.avg_pool2d(x, 2)
            for s in self.sizes:
                w = getattr(self, f"filters_{s}")
                wrapped = torch.nn.functional.pad(x - 0.5, (s // 2,) * 4, mode="circular")   # a texture tiles
                maps.append(torch.relu(torch.nn.functional.conv2d(wrapped, w)))
        return maps

    def forward(self, image) -> list:
        x = self._input(image)
        colour = torch.cat([x[0], torch.ones_like(x[0, :1])])                 # (4, H, W): RGB and a constant
        return [gram_matrix(colour)] + [gram_matrix(f) for f in self._maps(x)]

    def activation(self, image, block: int, channels) -> torch.Tensor:
        """DeepDream's objective: the mean over positions of the squared responses of ``channels`` (a list of
        filter indices) in feature block ``block`` (0 .. scales · len(sizes) - 1, as ``features``)."""
        maps = self.features(image)
        if not 0 <= int(block) < len(maps):
            raise ValueError(f"block must be in [0, {len(maps)}), got {block!r}")
        idx = torch.as_tensor(list(channels), dtype=torch.long)
        if idx.numel() == 0 or idx.min() < 0 or idx.max() >= self.channels:
            raise ValueError(f"channels must be filter indices in [0, {self.channels}), got {list(channels)}")
        return (maps[int(block)][0, idx] ** 2).mean()


def synthesize_texture(style, size=(64, 64), steps: int = 300, *, seed: int = 0, lr: float = 0.2,
                       network: RandomFeatures | None = None, progress: bool = False):
    """A texture of ``size`` (H, W) whose random-feature statistics match ``style`` (H', W', 3) in [0, 1].

    Starts from seeded noise and runs Adam on the pixels (through a sigmoid, so they stay in [0, 1]) against
    ``style_loss``. network: the ``RandomFeatures`` to use (seeded by ``seed`` when None). progress: a tqdm bar
    (``TQDM_DISABLE=1`` also hides it). Returns the image (H, W, 3) and the losses per step (steps,)."""
    steps = _check_count(steps, "steps")
    lr = _check_real(lr, "lr", low=0, low_open=True)
    H, W = (_check_count(v, "size") for v in size)
    net = network if network is not None else RandomFeatures(seed=seed)
    with torch.no_grad():
        target = [g.detach() for g in net(style)]
    g = torch.Generator().manual_seed(int(seed))
    logits = (0.5 * torch.randn(H, W, 3, generator=g)).requires_grad_(True)
    opt = torch.optim.Adam([logits], lr=lr)
    losses = []
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    for _ in tqdm(range(steps), desc="synthesize texture", disable=disable, leave=False):
        opt.zero_grad()
        loss = style_loss(net(torch.sigmoid(logits)), target)
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    return torch.sigmoid(logits).detach(), torch.tensor(losses)


# ---------------------------------------------------------------------------------- style images from nothing

def stripes(size: int = 64, period: float = 8.0, angle: float = 30.0, colors=((0.9, 0.8, 0.2), (0.1, 0.2, 0.6)),
            *, dtype=torch.float32) -> torch.Tensor:
    """(size, size, 3) soft stripes of ``period`` pixels at ``angle`` degrees, between two colours."""
    size = _check_count(size, "size")
    period = _check_real(period, "period", low=0, low_open=True)
    a = math.radians(_check_real(angle, "angle"))
    yy, xx = torch.meshgrid(torch.arange(size, dtype=torch.float64), torch.arange(size, dtype=torch.float64),
                            indexing="ij")
    t = 0.5 + 0.5 * torch.sin(2 * math.pi * (xx * math.cos(a) + yy * math.sin(a)) / period)
    c0, c1 = (torch.tensor(c, dtype=torch.float64) for c in colors)
    return (c0 + t[..., None] * (c1 - c0)).to(dtype)


def dots(size: int = 64, spacing: float = 10.0, radius: float = 3.0, colors=((0.95, 0.95, 0.9), (0.8, 0.1, 0.1)),
         *, dtype=torch.float32) -> torch.Tensor:
    """(size, size, 3) round dots of ``radius`` on a square grid of ``spacing`` pixels, edges smoothed."""
    size = _check_count(size, "size")
    spacing = _check_real(spacing, "spacing", low=0, low_open=True)
    radius = _check_real(radius, "radius", low=0, low_open=True)
    yy, xx = torch.meshgrid(torch.arange(size, dtype=torch.float64) + 0.5,
                            torch.arange(size, dtype=torch.float64) + 0.5, indexing="ij")
    dx = (xx % spacing) - spacing / 2
    dy = (yy % spacing) - spacing / 2
    t = torch.clamp(radius + 0.5 - torch.sqrt(dx ** 2 + dy ** 2), 0, 1)     # about one pixel of smoothing
    c0, c1 = (torch.tensor(c, dtype=torch.float64) for c in colors)
    return (c0 + t[..., None] * (c1 - c0)).to(dtype)


def marble(size: int = 64, seed: int = 0, *, dtype=torch.float32) -> torch.Tensor:
    """(size, size, 3) procedural marble: veins ``sin(x + turbulence)`` with turbulence a sum of seeded
    random Fourier waves (Perlin's marble, with sine waves for noise)."""
    size = _check_count(size, "size")
    g = torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0))
    yy, xx = torch.meshgrid(torch.arange(size, dtype=torch.float64), torch.arange(size, dtype=torch.float64),
                            indexing="ij")
    turbulence = torch.zeros_like(xx)
    for octave in range(4):                                                 # finer waves, weaker
        k = 2 ** octave
        for _ in range(3):
            freq = (torch.rand(2, generator=g, dtype=torch.float64) - 0.5) * 2 * math.pi * k * 4 / size
            phase = 2 * math.pi * float(torch.rand(1, generator=g, dtype=torch.float64))
            turbulence = turbulence + torch.sin(xx * freq[0] + yy * freq[1] + phase) / k
    t = 0.5 + 0.5 * torch.sin(2 * math.pi * xx / (size / 3) + 2.0 * turbulence)
    light = torch.tensor([0.93, 0.91, 0.86], dtype=torch.float64)
    vein = torch.tensor([0.35, 0.33, 0.38], dtype=torch.float64)
    return (vein + (t ** 0.4)[..., None] * (light - vein)).to(dtype)
