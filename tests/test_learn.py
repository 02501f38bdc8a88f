"""course.learning.reconstruction: single-image reconstruction through the soft rasterizer (lecture 13). The suite trains a few
steps only; whether the network learns the families is the bench's question (``bench learn``), not a test's."""
import pytest
import torch

from course.learning.reconstruction import (MeshReconstructor, ReconstructionSettings, batched_smoothness, evaluate_reconstruction,
                          load_pretrained_reconstructor, load_reconstructor, reconstruction_loss, retrieve,
                          save_reconstructor, shape_scores, train_reconstructor, train_step)
from course.inverse.losses import smoothness_loss
from course.mesh import Mesh
from course.learning.data import make_dataset

SETTINGS = ReconstructionSettings(size=16, subdivisions=1)


@pytest.fixture(scope="module")
def data():
    return make_dataset(1, families=("box", "cone", "torus", "vase"), views=2, size=16)


def test_the_network_starts_as_the_template_sphere_and_is_seeded(data):
    state = torch.get_rng_state()
    a, b, c = MeshReconstructor(SETTINGS), MeshReconstructor(SETTINGS), MeshReconstructor(
        ReconstructionSettings(size=16, subdivisions=1, seed=1))
    assert torch.equal(torch.get_rng_state(), state)                         # no global randomness consumed
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
    assert not torch.equal(a.encoder[0].weight, c.encoder[0].weight)
    verts = a(data.images[:, 0])
    assert verts.shape == (4, 42, 3) and a.faces.shape == (80, 3)            # icosphere(1)
    torch.testing.assert_close(verts, a.template.expand_as(verts), atol=0.05, rtol=0)


def test_the_loss_is_small_for_the_true_mesh_and_large_for_the_sphere(data):
    mesh, targets = data.meshes[0], data.silhouettes[:1]
    true_loss, _ = reconstruction_loss(mesh.verts[None], mesh.faces, data.cameras, targets, sigma=1e-4,
                                       smoothness=0.0)
    model = MeshReconstructor(SETTINGS)
    sphere_loss, _ = reconstruction_loss(model.template[None], model.faces, data.cameras, targets, smoothness=0.0)
    assert float(true_loss) < 0.1 < float(sphere_loss)


def test_a_few_training_steps_lower_the_loss(data):
    model = MeshReconstructor(SETTINGS)
    optimizer = torch.optim.Adam(model.parameters(), lr=2e-3)
    images, targets = data.images[:, 0], data.silhouettes
    losses = [train_step(model, optimizer, images, targets, data.cameras) for _ in range(8)]
    with torch.no_grad():
        final, per_shape = reconstruction_loss(model(images), model.faces, data.cameras, targets,
                                               sigma=SETTINGS.sigma, smoothness=SETTINGS.smoothness)
    assert float(final) < losses[0] - 0.02, losses
    assert per_shape.shape == (4,) and bool(torch.isfinite(per_shape).all())
    assert all(p.grad is not None and bool(torch.isfinite(p.grad).all()) for p in model.parameters())


def test_bad_input():
    with pytest.raises(ValueError, match="multiple of 8"):
        MeshReconstructor(ReconstructionSettings(size=20))
    model = MeshReconstructor(SETTINGS)
    with pytest.raises(ValueError, match="images must be"):
        model(torch.zeros(2, 16, 16))
    with pytest.raises(ValueError, match="targets"):
        reconstruction_loss(model.template[None], model.faces, [], torch.zeros(1, 2, 16, 16))


# ---- the training loop, the evaluation, the checkpoints ---------------------------------------------------

@pytest.fixture(scope="module")
def four_views():
    return make_dataset(2, families=("box", "cone", "vase"), views=4, size=16, dtype=torch.float32)


def test_train_reconstructor_lowers_the_loss_is_seeded_and_leaves_torch_alone(four_views):
    state = torch.get_rng_state()
    runs = [train_reconstructor(four_views, settings=SETTINGS, steps=10, batch=6, lr=3e-3, seed=s)
            for s in (0, 0, 1)]
    assert torch.equal(torch.get_rng_state(), state)
    (a, la), (b, lb), (_, lc) = runs
    assert la == lb and la != lc                                              # the seed picks the views
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
    assert sum(la[-3:]) / 3 < la[0] - 0.02, la
    assert not a.training


def test_batched_smoothness_is_the_loss_of_each_shape():
    model = MeshReconstructor(SETTINGS)
    verts = model.template + 0.05 * torch.randn(3, *model.template.shape, generator=torch.Generator().manual_seed(0))
    expected = torch.stack([smoothness_loss(v, model.faces) for v in verts])
    torch.testing.assert_close(batched_smoothness(verts, model.faces), expected)


def test_per_shape_cameras_match_one_call_per_shape(four_views):
    model = MeshReconstructor(SETTINGS)
    verts, cams = model(four_views.images[:2, 0]), four_views.cameras
    pairs = [[cams[0], cams[2]], [cams[3], cams[1]]]
    targets = torch.stack([four_views.silhouettes[0, [0, 2]], four_views.silhouettes[1, [3, 1]]])
    _, per_shape = reconstruction_loss(verts, model.faces, pairs, targets)
    for b in range(2):
        _, one = reconstruction_loss(verts[b:b + 1], model.faces, pairs[b], targets[b:b + 1])
        torch.testing.assert_close(per_shape[b:b + 1], one)
    with pytest.raises(ValueError, match="per-shape cameras"):
        reconstruction_loss(verts, model.faces, pairs[:1], targets)


def test_scores_of_hand_cases(four_views):
    mesh = four_views.meshes[0]
    perfect = shape_scores(mesh, mesh, resolution=16, samples=500)
    assert perfect["iou"] == 1.0 and perfect["chamfer"] < 1e-6               # float32 mesh, float64 samples
    shifted = shape_scores(Mesh(mesh.verts + 2.5, mesh.faces), mesh, resolution=16, samples=500)
    assert shifted["iou"] == 0.0 and shifted["chamfer"] > 0.5                 # moved out of the grid entirely
    assert torch.equal(retrieve(four_views, four_views.images[:, 0]), torch.arange(len(four_views)))


def test_evaluation_of_a_training_set_against_itself(four_views):
    model = MeshReconstructor(SETTINGS)
    rows = evaluate_reconstruction(model, four_views, four_views, resolution=16, samples=300)
    assert [r["family"] for r in rows] == ["box", "cone", "vase", "mean"]
    assert all(r["iou_retrieval"] == 1.0 and r["chamfer_retrieval"] < 1e-6 for r in rows)  # itself, retrieved
    # (Chamfer's distances come from torch.cdist's matrix-product form: zero to about 1e-10)
    assert all(0 <= r["iou_sphere"] < 1 and 0 <= r["iou_network"] < 1 for r in rows)
    assert rows[-1]["n"] == len(four_views)
    with pytest.raises(ValueError, match="images must be"):
        retrieve(four_views, torch.zeros(2, 8, 8, 3))


def test_a_checkpoint_round_trips(tmp_path, four_views):
    model, _ = train_reconstructor(four_views, settings=SETTINGS, steps=2, batch=2)
    save_reconstructor(model, tmp_path / "net.pt", note="two steps")
    again = load_reconstructor(tmp_path / "net.pt")
    assert again.note == "two steps" and again.settings == SETTINGS
    images = four_views.images[:, 0]
    torch.testing.assert_close(again(images), model(images))
    with pytest.raises(ValueError, match="no checkpoint"):
        load_reconstructor(tmp_path / "missing.pt")
    torch.save({"weights": 1}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a reconstructor checkpoint"):
        load_reconstructor(tmp_path / "other.pt")


def test_the_shipped_network_loads_and_reconstructs():
    model = load_pretrained_reconstructor()
    assert "bench learn" in model.note
    assert all(p.dtype == torch.float32 for p in model.state_dict().values() if p.is_floating_point())
    data = make_dataset(1, families=("capsule",), split="test", views=1, size=model.settings.size,
                        dtype=torch.float32)
    verts = model(data.images[:, 0])
    assert verts.shape == (1, model.template.shape[0], 3) and bool(torch.isfinite(verts).all())
    assert shape_scores(Mesh(verts[0], model.faces), data.meshes[0], samples=500)["iou"] > 0.5


def test_bad_training_input(four_views):
    with pytest.raises(ValueError, match="views must be at most"):
        train_reconstructor(four_views, settings=SETTINGS, steps=1, views=5)
    with pytest.raises(ValueError, match="network reads"):
        train_reconstructor(four_views, steps=1)                             # 16 px data, a 32 px network
    with pytest.raises(ValueError, match="lr"):
        train_reconstructor(four_views, settings=SETTINGS, steps=1, lr=0.0)


# The test-family mean voxel IoU of the two shipped networks in README's Table 1 (python -m course bench learn,
# inputs from any view): the checkpoints, run on the bench's 120 test shapes with the bench's input views, must
# give them back. The networks are float32, so the last digit may move on another CPU.
README_MEANS = {"mesh": 0.643, "voxel": 0.618}


def test_the_shipped_networks_reproduce_the_readme_means():
    from course.learning.data import voxel_iou, voxelize
    from course.learning.table import input_views
    from course.learning.voxels import load_pretrained_voxel_reconstructor
    data = make_dataset(20, families=("box", "cylinder", "cone", "capsule", "vase", "star"), split="test", views=24,
                        size=32, dtype=torch.float32)
    images = data.images[torch.arange(len(data)), input_views(data, "all", seed=1)]
    mesh, voxel = load_pretrained_reconstructor(), load_pretrained_voxel_reconstructor()
    assert "inputs all" in mesh.note and "inputs all" in voxel.note
    with torch.no_grad():
        verts, occupancy = mesh(images), voxel(images)
    truth = [voxelize(m) for m in data.meshes]
    iou = {"mesh": [voxel_iou(voxelize(Mesh(v.double(), mesh.faces)), t) for v, t in zip(verts, truth)],
           "voxel": [voxel_iou(o > 0.5, t) for o, t in zip(occupancy, truth)]}
    for method, values in iou.items():
        assert abs(sum(values) / len(values) - README_MEANS[method]) < 2e-3, method
    from pathlib import Path
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    table = readme[readme.index("### Learning through the renderer"):]
    assert f"| mesh network | {README_MEANS['mesh']:.3f} |" in table
    assert f"| voxel network | {README_MEANS['voxel']:.3f} (" in table


def test_the_networks_refuse_bad_images_and_accept_any_dtype():
    """A NaN pixel, colours far outside [0, 1], a wrong shape or an empty batch: a ValueError that names it (the
    shipped network used to answer NaN or vertices at 1e27). float64, float16, uint8 and numpy images run in the
    network's own dtype; uint8 is read as 0-255."""
    import numpy as np
    from course.learning.voxels import load_pretrained_voxel_reconstructor
    mesh_net, voxel_net = load_pretrained_reconstructor(), load_pretrained_voxel_reconstructor()
    data = make_dataset(1, families=("box",), split="test", views=1, size=32, dtype=torch.float32)
    images = data.images[:, 0]                                            # (1, 32, 32, 3) in [0, 1]
    with torch.no_grad():
        for net in (mesh_net, voxel_net):
            reference = net(images)
            for other in (images.double(), images.numpy(), images.double().numpy()):
                torch.testing.assert_close(net(other), reference, atol=1e-5, rtol=0)
            torch.testing.assert_close(net(images.half()), net(images.half().float()), atol=0, rtol=0)
            as_bytes = (images * 255).round().to(torch.uint8)
            torch.testing.assert_close(net(as_bytes), net(as_bytes.float() / 255))
            torch.testing.assert_close(net(np.asarray(as_bytes)), net(as_bytes.float() / 255))
            bad = images.clone()
            bad[0, 3, 4, 1] = float("nan")
            with pytest.raises(ValueError, match="NaN"):
                net(bad)
            with pytest.raises(ValueError, match=r"in \[0, 1\].*to 7.05e\+29"):
                net(images * 1e30)
            with pytest.raises(ValueError, match=r"must be \(B, 32, 32, 3\)"):
                net(images[:, :16])
            with pytest.raises(ValueError, match="empty"):
                net(images[:0])
