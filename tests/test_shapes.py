"""course.learning.shapes and course.learning.data: procedural shape families, their views, their voxels (lecture 13's data).

Oracles: the signed volume of a known cube; the rasterizer's own back-face culling (an outward closed mesh
shows the same faces with and without it); voxel counts of boxes worked out by hand; a generalised winding
number (solid angles, an independent inside test) against the ray-parity voxeliser.
"""
import math

import numpy as np
import pytest
import torch

from course.inverse import circle_views
from course.mesh import Mesh
from course.models import cube, icosphere
from course.raster import rasterize
from course.learning.data import (BACKGROUND, HELD_OUT, SPLITS, make_dataset, make_splits, render_views,
                               shape_seed, silhouette_iou_table, view_cameras, voxel_iou, voxelize, aspect_ratios)
from course.learning.shapes import M_AROUND, FAMILIES, _polygon_radius, aspect_ratio, boundary_edges, make_shape, signed_volume

SEEDS = range(12)


@pytest.fixture(scope="module")
def shapes():
    return {family: [make_shape(family, s) for s in SEEDS] for family in FAMILIES}


# ---- the meshes --------------------------------------------------------------------------------------------

def test_every_shape_is_closed_outward_finite_and_normalised(shapes):
    for family, meshes in shapes.items():
        for seed, mesh in zip(SEEDS, meshes):
            where = f"{family} seed {seed}"
            assert boundary_edges(mesh.faces).shape == (0, 2), where         # every edge in two faces, one each way
            assert signed_volume(mesh) > 0.05, where                          # outward (and not flat)
            assert bool(torch.isfinite(mesh.verts).all()), where
            assert float(mesh.face_areas().min()) > 1e-4, where              # no degenerate faces
            radius = mesh.verts.norm(dim=1)
            assert float(radius.max()) == pytest.approx(1.0, abs=1e-6), where  # fits the unit sphere
            centre = (mesh.verts.max(0).values + mesh.verts.min(0).values) / 2
            assert float(centre.abs().max()) < 1e-6, where                     # bounding box centred
            assert 250 <= mesh.num_faces <= 500, where


def test_outward_means_front_facing_to_the_rasterizer(shapes):
    """Seen from outside, a closed mesh shows front faces only: culling back faces changes no pixel's face.
    (Wound inward, culling would remove the near side and show the far one.)"""
    cameras = circle_views(3, elevations=(30.0, -20.0), size=24)
    for family, meshes in shapes.items():
        for camera in cameras:
            kept, culled = rasterize(meshes[0], camera), rasterize(meshes[0], camera, cull_backfaces=True)
            assert bool(kept.mask.any()), family
            assert torch.equal(kept.face_id, culled.face_id), family
        inward = Mesh(meshes[0].verts, meshes[0].faces[:, [0, 2, 1]])
        assert signed_volume(inward) == pytest.approx(-signed_volume(meshes[0]))


def test_boundary_edges_finds_holes_flips_and_the_cube_volume():
    box = cube(2.0, dtype=torch.float64)
    assert boundary_edges(box.faces).shape == (0, 2)
    assert signed_volume(box) == pytest.approx(8.0)
    holed = box.faces[1:]                                                     # one face missing: its 3 edges
    a, b, c = box.faces[0].tolist()
    expected = sorted(tuple(sorted(e)) for e in ((a, b), (b, c), (c, a)))
    assert sorted(map(tuple, boundary_edges(holed).tolist())) == expected
    flipped = box.faces.clone()
    flipped[3] = flipped[3, [0, 2, 1]]                                        # one face wound inward
    assert boundary_edges(flipped).shape == (3, 2)


def test_same_seed_same_shape_other_seed_other_shape(shapes):
    for family in FAMILIES:
        again = make_shape(family, 5)
        assert torch.equal(again.verts, shapes[family][5].verts) and torch.equal(again.faces, shapes[family][5].faces)
        assert not torch.equal(shapes[family][5].verts, shapes[family][6].verts), family
    double = make_shape("vase", 5, dtype=torch.float64)
    assert double.dtype == torch.float64
    torch.testing.assert_close(double.verts.float(), shapes["vase"][5].verts)


def test_each_family_varies_in_proportion(shapes):
    for family, meshes in shapes.items():
        ratios = [aspect_ratio(m) for m in meshes]
        assert max(ratios) / min(ratios) > 1.4, (family, ratios)              # tall and flat ones in 12 seeds


def test_polygon_sections_keep_their_corners():
    """The ring samples include every corner of a star (else its tips are cut off) and lie on its sides: the
    sampled polygon's area (triangle fan, ½ Σ r_j r_j+1 sin Δθ) is the star's, n ρ sin(π / n) for n points, inner
    radius ρ and outer radius 1. (Five points would fail: 36° is not a multiple of 360° / 24.)"""
    theta = 2 * math.pi * np.arange(M_AROUND) / M_AROUND
    for n in (3, 4, 6):
        r = _polygon_radius(theta, np.tile([1.0, 0.5], n))
        area = 0.5 * (r * np.roll(r, -1)).sum() * math.sin(2 * math.pi / M_AROUND)
        assert area == pytest.approx(n * 0.5 * math.sin(math.pi / n)), n
    square = _polygon_radius(theta, np.full(4, math.sqrt(2) / 2), phase=math.pi / 4)
    x, z = square * np.sin(theta), square * np.cos(theta)
    np.testing.assert_allclose(np.maximum(abs(x), abs(z)), 0.5)               # every sample on the unit square


def test_make_shape_rejects_bad_input():
    with pytest.raises(ValueError, match="family must be one of"):
        make_shape("teapot", 0)
    for seed in (-1, 1.5, True):
        with pytest.raises(ValueError, match="seed"):
            make_shape("box", seed)


# ---- the dataset -------------------------------------------------------------------------------------------

def test_dataset_shapes_labels_and_views_match_the_renderer():
    ds = make_dataset(2, families=("cone", "torus"), views=3, size=16)
    assert len(ds) == 4 and ds.families == ("cone", "torus") and ds.labels.tolist() == [0, 0, 1, 1]
    assert ds.silhouettes.shape == (4, 3, 16, 16) and ds.images.shape == (4, 3, 16, 16, 3) and len(ds.cameras) == 3
    for n, mesh in enumerate(ds.meshes):
        assert torch.equal(mesh.verts, make_shape(ds.families[ds.labels[n]], int(ds.seeds[n])).verts)
        for v, camera in enumerate(ds.cameras):
            assert torch.equal(ds.silhouettes[n, v].bool(), rasterize(mesh, camera).mask)
        background = ds.images[n][ds.silhouettes[n] == 0]                    # (P, 3) pixels off the shape
        assert torch.equal(background, torch.tensor(BACKGROUND).expand_as(background))
        assert 0.05 < float(ds.silhouettes[n].mean()) < 0.8                   # in frame, not filling it
        border = ds.silhouettes[n][..., [0, -1], :].sum() + ds.silhouettes[n][..., :, [0, -1]].sum()
        assert float(border) == 0                                             # never cut off by the frame
    again = make_dataset(2, families=("cone", "torus"), views=3, size=16)
    assert torch.equal(again.images, ds.images) and torch.equal(again.seeds, ds.seeds)


def test_view_cameras_look_at_the_origin_a_golden_angle_apart():
    cameras = view_cameras(3, size=16, elevation=30.0, distance=3.2)
    golden = math.pi * (3 - math.sqrt(5))
    for k, camera in enumerate(cameras):
        eye = camera.eye.double()
        assert float(eye.norm()) == pytest.approx(3.2, rel=1e-5)
        assert math.degrees(math.asin(float(eye[1]) / 3.2)) == pytest.approx(30.0, abs=1e-3)
        assert math.atan2(float(eye[0]), float(eye[2])) % (2 * math.pi) == pytest.approx(k * golden % (2 * math.pi),
                                                                                          abs=1e-5)
        centre, _ = camera.project(torch.zeros(1, 3))
        torch.testing.assert_close(centre, torch.tensor([[8.0, 8.0]]))           # the origin at the image centre
    with pytest.raises(ValueError, match="elevation"):
        view_cameras(2, elevation=90.0)
    with pytest.raises(ValueError, match="distance"):
        view_cameras(2, distance=0.5)


def test_render_views_shades_with_the_light_fixed_in_the_world():
    mesh = make_shape("box", 3)
    cameras = view_cameras(2, size=20)
    sils, images = render_views(mesh, cameras)
    lit = images[sils.bool()]                                                 # (P, 3)
    assert lit.shape[0] > 20 and float(lit.min()) >= 0 and float(lit.max()) <= 1
    assert len(torch.unique(lit, dim=0)) >= 2                                 # faces turned differently differ


def test_splits_never_share_a_shape_and_hold_a_family_out():
    splits = make_splits(3, 2, 2, views=1, size=8)
    assert set(splits) == set(SPLITS)
    for name in ("train", "val", "test"):
        assert not set(splits[name].families) & set(HELD_OUT)
        assert len(splits[name]) == {"train": 3, "val": 2, "test": 2}[name] * (len(FAMILIES) - len(HELD_OUT))
    assert splits["held_out"].families == HELD_OUT
    seeds = [set(splits[name].seeds.tolist()) for name in SPLITS]
    assert sum(map(len, seeds)) == len(set().union(*seeds))                   # no seed in two splits
    assert shape_seed(0, "train", "box", 0) == shape_seed(0, "train", "box", 0) != shape_seed(1, "train", "box", 0)


def test_families_are_told_apart_by_their_silhouettes():
    ds = make_dataset(8, views=1, size=24)
    table = silhouette_iou_table(ds)
    assert table.shape == (len(FAMILIES),) * 2 and torch.allclose(table, table.T)
    masks = ds.silhouettes[:, 0].bool()                                       # the naive loop for boxes vs cones
    box, cone = (torch.nonzero(ds.labels == ds.families.index(f))[:, 0].tolist() for f in ("box", "cone"))
    naive = [float((masks[i] & masks[j]).sum() / (masks[i] | masks[j]).sum()) for i in box for j in cone]
    assert float(table[0, 2]) == pytest.approx(sum(naive) / len(naive))
    naive = [float((masks[i] & masks[j]).sum() / (masks[i] | masks[j]).sum()) for i in box for j in box if i != j]
    assert float(table[0, 0]) == pytest.approx(sum(naive) / len(naive))
    within = torch.diagonal(table)
    across = (table.sum() - within.sum()) / (table.numel() - len(within))
    assert float(within.mean()) > float(across) + 0.05
    assert float(within.max()) < 0.95                                         # no family is one shape
    ratios = aspect_ratios(ds)
    assert set(ratios) == set(FAMILIES) and all(len(r) == 8 for r in ratios.values())


def test_dataset_rejects_bad_input():
    with pytest.raises(ValueError, match="families"):
        make_dataset(1, families="box")
    with pytest.raises(ValueError, match="families"):
        make_dataset(1, families=("box", "box"))
    with pytest.raises(ValueError, match="n_per_family"):
        make_dataset(0)
    with pytest.raises(ValueError, match="views"):
        make_dataset(1, views=0)
    with pytest.raises(ValueError, match="views"):
        make_dataset(1, views=["a camera"])
    with pytest.raises(ValueError, match="split"):
        make_dataset(1, split="dev")
    with pytest.raises(ValueError, match="n_val"):
        make_splits(1, 0, 1)
    with pytest.raises(ValueError, match="no family"):
        make_splits(1, 1, 1, held_out=FAMILIES)


# ---- voxels ------------------------------------------------------------------------------------------------

def winding_number(mesh, points):
    """(N,) the generalised winding number of a closed mesh at points (N, 3): Σ solid angles / 4π (Van
    Oosterom & Strackee's formula), 1 inside and 0 outside an outward mesh. An inside test with no rays."""
    verts, faces = mesh.verts.double(), mesh.faces
    a, b, c = (verts[faces[:, k]][None] - points[:, None] for k in range(3))  # (N, F, 3) each
    la, lb, lc = a.norm(dim=-1), b.norm(dim=-1), c.norm(dim=-1)
    det = (a * torch.linalg.cross(b, c, dim=-1)).sum(-1)
    den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
    return (2 * torch.atan2(det, den)).sum(1) / (4 * math.pi)


def test_voxelize_agrees_with_the_winding_number(shapes):
    R = 12
    centres = -1 + (torch.arange(R, dtype=torch.float64) + 0.5) * (2 / R)
    grid = torch.stack(torch.meshgrid(centres, centres, centres, indexing="ij"), -1)  # (R, R, R, 3)
    for family in FAMILIES:
        mesh = shapes[family][1]
        occupancy = voxelize(mesh, R)
        inside = winding_number(mesh, grid.reshape(-1, 3)).reshape(R, R, R) > 0.5
        assert torch.equal(occupancy, inside), family
        assert 0 < int(occupancy.sum()) < R ** 3


def test_voxelize_counts_boxes_by_hand_and_spheres_by_volume():
    box = cube(1.0, dtype=torch.float64)                                      # [-0.5, 0.5]³: 4 of 8 centres a side
    assert int(voxelize(box, 8).sum()) == 64
    shifted = Mesh(box.verts + torch.tensor([0.25, 0.0, 0.0], dtype=torch.float64), box.faces)  # one voxel along x
    assert voxel_iou(voxelize(box, 8), voxelize(shifted, 8)) == pytest.approx(48 / 80)  # 4·4·3 of 64 + 64 - 48
    on_centres = cube(1.75, dtype=torch.float64)                              # faces through voxel centres
    occupancy = voxelize(on_centres, 8)
    assert int(occupancy.sum()) == 7 ** 3                                     # half-open: one side of each face
    assert int(occupancy[0].sum()) == 49 and int(occupancy[-1].sum()) == 0   # whole layers, no stray voxels
    sphere = icosphere(2, 0.8, dtype=torch.float64)
    volume = int(voxelize(sphere, 24).sum()) * (2 / 24) ** 3
    assert volume == pytest.approx(signed_volume(sphere), rel=0.02)


def test_voxel_iou_and_bad_input():
    a = torch.zeros(4, 4, 4, dtype=torch.bool)
    b = a.clone()
    assert voxel_iou(a, b) == 1.0                                             # both empty: nothing to miss
    a[0, 0, :2], b[0, 0, 1:3] = True, True
    assert voxel_iou(a, b) == pytest.approx(1 / 3)
    with pytest.raises(ValueError, match="same shape"):
        voxel_iou(a, b[:2])
    with pytest.raises(ValueError, match="Mesh"):
        voxelize(np.zeros((3, 3)), 8)
    with pytest.raises(ValueError, match="resolution"):
        voxelize(cube(), 0)
