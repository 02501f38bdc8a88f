"""course.learning.voxels: the voxel network of lecture 13's Table 1, supervised through a projection of its grid;
and ``reconstruction.training_batches``, the batches both networks train on."""
import pytest
import torch

from course.learning.data import make_dataset, voxelize
from course.learning.reconstruction import training_batches
from course.learning.voxels import (VoxelReconstructor, VoxelSettings, load_voxel_reconstructor,
                                    project_occupancy, save_voxel_reconstructor, train_voxel_reconstructor,
                                    voxel_loss, voxel_mesh)
from course.mesh import Mesh

SETTINGS = VoxelSettings(size=16, resolution=16, samples=32)


@pytest.fixture(scope="module")
def data():
    return make_dataset(1, families=("box", "cone", "capsule"), views=4, size=16, dtype=torch.float32)


def test_the_projection_of_a_true_grid_is_the_silhouette(data):
    """A shape's own occupancy at 32³, projected, matches its rasterized silhouettes up to the grid's steps."""
    big = make_dataset(1, families=("box", "cone", "capsule"), views=3, size=32, dtype=torch.float32)
    grids = torch.stack([voxelize(m, 32) for m in big.meshes]).float()
    sils = project_occupancy(grids, big.cameras, samples=96)
    assert sils.shape == (3, 3, 32, 32) and float(sils.min()) >= 0 and float(sils.max()) <= 1
    both = (sils * big.silhouettes).sum()
    iou = float(both / (sils + big.silhouettes - sils * big.silhouettes).sum())
    assert iou > 0.88, iou                                              # a voxel is 1.1 pixels wide here
    empty = project_occupancy(torch.zeros(1, 8, 8, 8), big.cameras[:1])
    assert float(empty.abs().max()) == 0


def test_per_shape_cameras_are_each_shapes_own(data):
    grids = torch.rand(3, 16, 16, 16, generator=torch.Generator().manual_seed(0))
    shared = project_occupancy(grids, data.cameras[:2], samples=16)
    own = project_occupancy(grids, [data.cameras[:2], data.cameras[2:], data.cameras[1:3]], samples=16)
    assert torch.equal(own[0], shared[0])
    assert torch.equal(own[1], project_occupancy(grids[1:2], data.cameras[2:], samples=16)[0])


def test_the_network_starts_as_the_template_sphere_is_seeded_and_learns(data):
    state = torch.get_rng_state()
    a, b = VoxelReconstructor(SETTINGS), VoxelReconstructor(SETTINGS)
    assert torch.equal(torch.get_rng_state(), state)
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
    occupancy = a(data.images[:, 0])
    assert occupancy.shape == (3, 16, 16, 16)
    sure = a.template.abs() > 0.5                                       # voxels not on the sphere's boundary
    assert torch.equal((occupancy > 0.5)[:, sure], (a.template > 0)[sure].expand(3, -1))   # the sphere, r = 0.6
    loss, per_shape = voxel_loss(occupancy, data.cameras, data.silhouettes, samples=16)
    loss.backward()
    assert per_shape.shape == (3,) and all(p.grad is not None and bool(torch.isfinite(p.grad).all())
                                           for p in a.parameters())
    _, losses = train_voxel_reconstructor(data, settings=SETTINGS, steps=12, batch=3, views=2, lr=5e-3)
    assert len(losses) == 12 and losses[-1] < losses[0] - 0.02, losses
    one, _ = train_voxel_reconstructor(data, settings=SETTINGS, steps=2, batch=3, views=2, lr=5e-3)
    two, _ = train_voxel_reconstructor(data, settings=SETTINGS, steps=2, batch=3, views=2, lr=5e-3)
    assert all(torch.equal(p, q) for p, q in zip(one.parameters(), two.parameters()))


def test_voxel_mesh_is_the_grids_surface():
    R = 16
    centres = -1 + (torch.arange(R, dtype=torch.float64) + 0.5) * (2 / R)
    r = torch.stack(torch.meshgrid(centres, centres, centres, indexing="ij"), -1).norm(dim=-1)
    mesh = voxel_mesh((r < 0.7).double())
    assert isinstance(mesh, Mesh)
    radii = mesh.verts.norm(dim=1)
    assert float((radii - 0.7).abs().max()) < 2 / R                     # within a voxel of the sphere
    assert voxel_mesh(torch.zeros(R, R, R)) is None


def test_a_checkpoint_round_trips(tmp_path, data):
    model = VoxelReconstructor(SETTINGS)
    save_voxel_reconstructor(model, tmp_path / "v.pt", note="made here")
    loaded = load_voxel_reconstructor(tmp_path / "v.pt")
    assert loaded.note == "made here" and loaded.settings == SETTINGS
    assert torch.equal(loaded(data.images[:, 0]), model(data.images[:, 0]))
    torch.save({"settings": {}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a voxel reconstructor"):
        load_voxel_reconstructor(tmp_path / "other.pt")


def test_training_batches_first_and_all(data):
    first = list(training_batches(data, steps=5, batch=2, views=2, input_views="first", seed=4))
    every = list(training_batches(data, steps=5, batch=2, views=2, input_views="all", seed=4))
    assert all(int(i.max()) == 0 and p.shape == (2, 2) for _, i, p in first)
    for idx, inputs, pick in every:
        assert pick.shape == (2, 2) and inputs.shape == (2,)
        assert not bool((pick == inputs[:, None]).any())                # never supervised by its own input view
    assert len({int(v) for _, i, _ in every for v in i}) > 1
    seen = torch.cat([idx for idx, _, _ in first[:3]])                  # an epoch of 3 shapes, then the next
    assert sorted(seen[:3].tolist()) == [0, 1, 2]


def test_bad_input(data):
    with pytest.raises(ValueError, match="multiple of 8"):
        VoxelReconstructor(VoxelSettings(size=20))
    with pytest.raises(ValueError, match="multiple of 4"):
        VoxelReconstructor(VoxelSettings(resolution=18))
    with pytest.raises(ValueError, match="images must be"):
        VoxelReconstructor(SETTINGS)(torch.zeros(2, 16, 16))
    with pytest.raises(ValueError, match="occupancy must be"):
        project_occupancy(torch.zeros(2, 8, 8, 4), data.cameras)
    with pytest.raises(ValueError, match="input_views"):
        training_batches(data, steps=1, batch=1, views=1, input_views="random")
    with pytest.raises(ValueError, match="at most the dataset's 3 views"):
        training_batches(data, steps=1, batch=1, views=4, input_views="all")


def test_voxelize_all_stacks_the_grids_of_voxelize():
    from course.learning.data import make_dataset, voxelize, voxelize_all
    data = make_dataset(1, families=("box", "torus"), views=1, size=8, dtype=torch.float64)
    grids = voxelize_all(data.meshes, 16, progress=True)
    assert grids.shape == (2, 16, 16, 16) and grids.dtype == torch.bool
    assert all(torch.equal(g, voxelize(m, 16)) for g, m in zip(grids, data.meshes))
    with pytest.raises(ValueError, match="empty"):
        voxelize_all([])
