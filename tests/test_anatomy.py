"""What a fit gets wrong, by region (course.inverse.anatomy): each region found where it is planted."""
from __future__ import annotations

import pytest
import torch

from course import models
from course.camera import Camera
from course.inverse.anatomy import REGIONS, error_anatomy, inside_masks
from course.mesh import Mesh

BG = torch.tensor([0.2, 0.4, 0.8], dtype=torch.float64)
SURFACE = torch.tensor([0.8, 0.5, 0.2], dtype=torch.float64)


def _scene(views=2, size=24):
    """A disc-shaped target on the background: masks (M, H, W) and images (M, H, W, 3)."""
    ii, jj = torch.meshgrid(torch.arange(size) + 0.5, torch.arange(size) + 0.5, indexing="ij")
    disc = (ii - size / 2) ** 2 + (jj - size / 2) ** 2 < (size / 4) ** 2
    masks = disc.expand(views, size, size).clone()
    images = torch.where(masks[..., None], SURFACE, BG)
    return masks, images


def test_a_perfect_fit_has_no_error_anywhere():
    masks, images = _scene()
    a = error_anatomy(images.clone(), images, masks, BG)
    assert a["sse"] == 0 and all(a[r]["share"] == 0 for r in REGIONS)
    assert sum(a[r]["pixels"] for r in REGIONS) == masks.numel()
    assert a["regions"]["edge"].sum() > 0 and a["regions"]["floaters"].sum() == 0


def test_each_planted_error_lands_in_its_region():
    masks, images = _scene()
    render = images.clone()
    render[0, 1:3, 1:3] = SURFACE                     # a blob off the target, far from its outline: a floater
    render[1, 11:13, 11:13] = BG                      # the background through the target's middle: see-through
    render[1, 6:8, 12] = torch.tensor([0.1, 0.1, 0.1], dtype=torch.float64)   # dark, but covered: shading
    a = error_anatomy(render, images, masks, BG)
    assert (a["floaters"]["pixels"], a["floaters"]["views"]) == (4, 1)
    assert (a["see-through"]["pixels"], a["see-through"]["views"]) == (4, 1)
    sse = ((render - images) ** 2).sum(-1)
    assert abs(a["floaters"]["share"] - float(sse[0, 1:3, 1:3].sum()) / float(sse.sum())) < 1e-12
    assert abs(a["see-through"]["share"] - float(sse[1, 11:13, 11:13].sum()) / float(sse.sum())) < 1e-12
    assert abs(sum(a[r]["share"] for r in REGIONS) - 1) < 1e-12
    assert a["worst_view"] == 1 and a["psnr"][0] > a["psnr"][1]
    faint = images.clone()
    faint[0, 1:3, 1:3] = BG + 0.05                    # within the tolerance of the background: not a floater
    assert error_anatomy(faint, images, masks, BG)["floaters"]["pixels"] == 0
    assert error_anatomy(faint, images, masks, BG, tolerance=0.01)["floaters"]["pixels"] == 4


def test_the_outline_takes_the_pixels_beside_the_silhouette():
    masks, images = _scene(views=1)
    render = torch.where(masks[..., None], BG, SURFACE)          # everything wrong
    a = error_anatomy(render, images, masks, BG)
    edge = a["regions"]["edge"][0]
    inner = masks[0] & ~edge
    # an edge pixel has a neighbour on the other side of the silhouette, and no other pixel has
    padded = torch.nn.functional.pad(masks[0][None, None].float(), (1, 1, 1, 1), mode="replicate")[0, 0]
    windows = padded.unfold(0, 3, 1).unfold(1, 3, 1)
    mixed = (windows.amin((-1, -2)) != windows.amax((-1, -2)))
    assert torch.equal(edge, mixed)
    assert torch.equal(a["regions"]["see-through"][0], inner)


def test_inside_pixels_are_an_open_box_seen_through_its_opening():
    cube = models.cube(dtype=torch.float64)
    centres = cube.verts[cube.faces].mean(1)
    open_box = Mesh(cube.verts, cube.faces[centres[:, 1] < 0.99])           # the top (y = 1) taken off
    above = Camera.look_at((0.0, 4.0, 0.3), (0.0, 0.0, 0.0), fov_y=40.0, width=24, height=24, dtype=torch.float64)
    below = Camera.look_at((0.0, -4.0, 0.3), (0.0, 0.0, 0.0), fov_y=40.0, width=24, height=24, dtype=torch.float64)
    ortho = Camera.look_at((0.0, 4.0, 0.3), (0.0, 0.0, 0.0), ortho_height=3.0, width=24, height=24,
                           dtype=torch.float64)
    closed = inside_masks(cube, [above, below])
    assert int(closed.sum()) == 0
    opened = inside_masks(open_box, [above, below, ortho])
    assert int(opened[0].sum()) > 100 and int(opened[1].sum()) == 0 and int(opened[2].sum()) > 100


def test_the_teapot_shows_its_inside_through_the_gap_under_the_lid():
    teapot = models.teapot(6, dtype=torch.float64)
    top = Camera.look_at((0.0, 3.0, 0.1), (0.0, 0.0, 0.0), fov_y=40.0, width=64, height=64, dtype=torch.float64)
    side = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=64, height=64, dtype=torch.float64)
    masks = inside_masks(teapot, [top, side])
    assert int(masks[0].sum()) > 30 and int(masks[1].sum()) == 0
    pixels = masks[0].nonzero().double()
    ring = pixels[pixels[:, 1] < 45]                                            # the spout's opening is further right
    radius = (ring - ring.mean(0)).norm(dim=1)                                  # about the ring's own centre
    assert len(ring) > 0.8 * len(pixels) and float((radius - radius.median()).abs().max()) < 1.5


@pytest.mark.parametrize("bad, match", [
    (dict(renders=torch.zeros(2, 8, 8)), "shape"),
    (dict(masks=torch.zeros(2, 8, 9, dtype=torch.bool)), "masks must have shape"),
    (dict(renders=torch.full((2, 8, 8, 3), float("nan"))), "NaN"),
    (dict(inside=torch.zeros(1, 8, 8, dtype=torch.bool)), "inside must have"),
    (dict(background=torch.zeros(4)), "background"),
    (dict(tolerance=0.0), "tolerance"),
])
def test_bad_input_is_named(bad, match):
    args = dict(renders=torch.zeros(2, 8, 8, 3), targets=torch.zeros(2, 8, 8, 3),
                masks=torch.zeros(2, 8, 8, dtype=torch.bool), background=BG)
    kwargs = {k: bad.pop(k) for k in ("inside", "tolerance") if k in bad}
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        error_anatomy(*args.values(), **kwargs)
