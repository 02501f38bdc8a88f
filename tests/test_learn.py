"""course.learn: single-image reconstruction through the soft rasterizer (lecture 13). The suite trains a few
steps only; whether the network learns the families is the bench's question, not a test's."""
import pytest
import torch

from course.learn import MeshReconstructor, ReconstructionSettings, reconstruction_loss, train_step
from course.shape_data import make_dataset

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
