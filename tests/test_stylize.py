"""Style transfer and DeepDream through the renderer (course.style.transfer)."""
import math

import pytest
import torch

from course import models
from course.mesh import Mesh
from course.style import RandomFeatures, stripes
from course.style.transfer import (deep_dream_mesh, random_directions, render_texture, stylize_mesh, view_camera)


def test_random_directions_are_uniform_on_the_sphere_and_seeded():
    """Unit vectors; the caps |z| > 0.9 hold 10% of the sphere's area and get 10% of 40000 directions (5
    standard errors: 0.75%); the mean direction is 0; the same seed gives the same directions."""
    d = random_directions(40000, torch.Generator().manual_seed(0))
    assert d.shape == (40000, 3) and d.dtype == torch.float64
    assert float((d.norm(dim=1) - 1).abs().max()) < 1e-12
    assert abs(float((d[:, 2].abs() > 0.9).double().mean()) - 0.1) < 5 * math.sqrt(0.09 / 40000)
    assert float(d.mean(0).abs().max()) < 5 * math.sqrt(1 / 3 / 40000)
    assert torch.equal(random_directions(5, torch.Generator().manual_seed(1)),
                       random_directions(5, torch.Generator().manual_seed(1)))
    assert random_directions(3, torch.Generator().manual_seed(1), dtype=torch.float32).dtype == torch.float32


def test_a_view_straight_down_the_up_axis_is_a_valid_camera():
    cam = view_camera(torch.tensor([0.0, 1.0, 0.0]), torch.zeros(3), 3.0, 16)
    assert torch.isfinite(cam.R).all() and abs(float(torch.det(cam.R)) - 1) < 1e-12
    xy, z = cam.project(torch.zeros(1, 3, dtype=torch.float64))
    assert torch.allclose(xy, torch.tensor([[8.0, 8.0]], dtype=torch.float64)) and abs(float(z[0]) - 3) < 1e-12


def _scene(size=32):
    mesh = models.teapot(3, dtype=torch.float64)
    cam = view_camera(torch.tensor([0.6, 0.5, 0.8]), torch.zeros(3), 3.0, size)
    g = torch.Generator().manual_seed(0)
    texture = torch.rand(16, 16, 3, generator=g, dtype=torch.float64)
    return mesh, cam, texture


def test_the_soft_textured_image_approaches_the_hard_one_and_differentiates_both():
    """With a small σ the soft image is the z-buffer's away from the edges and seams (the soft one blends uvs
    across them): 90% of the pixels within 0.02 of it. The gradient reaches the vertices and the texture."""
    mesh, cam, texture = _scene()
    hard = render_texture(mesh.verts, mesh.faces, mesh.uvs, texture, cam, renderer="hard")
    soft = render_texture(mesh.verts, mesh.faces, mesh.uvs, texture, cam, renderer="soft", sigma=1e-6, gamma=1e-5)
    assert float(((hard - soft).abs().amax(-1) < 0.02).double().mean()) > 0.88
    for renderer in ("soft", "hard"):
        v = mesh.verts.clone().requires_grad_(True)
        t = texture.clone().requires_grad_(True)
        image = render_texture(v, mesh.faces, mesh.uvs, t, cam, renderer=renderer)
        (image * torch.linspace(0, 1, 3, dtype=torch.float64)).sum().backward()
        assert torch.isfinite(v.grad).all() and torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0
    background = render_texture(mesh.verts, mesh.faces, mesh.uvs, texture, cam, background=(0.2, 0.3, 0.4))
    assert torch.allclose(background[0, 0], torch.tensor([0.2, 0.3, 0.4], dtype=torch.float64), atol=1e-6)


def test_the_nmr_textured_image_is_the_z_buffers_and_adds_an_edge_gradient():
    """Kato et al.'s renderer: the forward pass is the z-buffer's image, bit for bit; the texture's gradient is
    the z-buffer's; the vertices get more than the z-buffer gives them (the edge terms), and only there."""
    mesh, cam, texture = _scene()
    grads = {}
    for renderer in ("hard", "nmr"):
        v = mesh.verts.clone().requires_grad_(True)
        t = texture.clone().requires_grad_(True)
        image = render_texture(v, mesh.faces, mesh.uvs, t, cam, renderer=renderer, background=(0.2, 0.3, 0.4))
        (image * torch.linspace(0, 1, 3, dtype=torch.float64)).sum().backward()
        grads[renderer] = (image.detach(), v.grad, t.grad)
    assert torch.equal(grads["hard"][0], grads["nmr"][0])
    assert torch.allclose(grads["hard"][2], grads["nmr"][2], rtol=0, atol=1e-12)
    extra = (grads["nmr"][1] - grads["hard"][1]).norm(dim=1)
    assert torch.isfinite(extra).all() and float(extra.max()) > 1e-3


def test_style_transfer_lowers_the_style_loss_and_keeps_the_shape():
    """A short seeded run: the style term falls, the vertices move a little (the content term), and the same
    seed gives the same run; with geometry=False the vertices stay put."""
    mesh = models.teapot(2, dtype=torch.float64)
    net = RandomFeatures(sizes=(3, 5), channels=8, scales=2)
    run = stylize_mesh(mesh, stripes(32), steps=12, size=32, texture_size=16, network=net, snapshot_every=5)
    assert run.losses.shape == (12,) and float(run.losses[-3:].mean()) < 0.9 * float(run.losses[:3].mean())
    moved = float((run.verts - mesh.verts).norm(dim=1).max())
    assert 0 < moved < 0.1
    assert run.texture.shape == (16, 16, 3) and float(run.texture.min()) >= 0 and float(run.texture.max()) <= 1
    assert [s[0] for s in run.snapshots] == [0, 5, 10, 11]
    again = stylize_mesh(mesh, stripes(32), steps=12, size=32, texture_size=16, network=net)
    assert torch.equal(again.verts, run.verts) and torch.equal(again.texture, run.texture)
    still = stylize_mesh(mesh, stripes(32), steps=3, size=32, texture_size=16, network=net, geometry=False)
    assert torch.equal(still.verts, mesh.verts.double())
    kato = stylize_mesh(mesh, stripes(32), steps=3, size=32, texture_size=16, network=net, renderer="nmr")
    assert 0 < float((kato.verts - mesh.verts).norm(dim=1).max()) < 0.1


def test_the_style_bench_compares_every_way_seed_by_seed():
    """``course.bench.style``: every way of WAYS from a seed, judged twice (a small network and tiny runs: the
    rows' shape, not the course's numbers; one seed says nothing is measurable); the table gives each way's range over the seeds and, per pair
    of ways and judge, the per-seed differences, measurable only when their mean exceeds their spread."""
    from course.bench.style import PAIRS, WAYS, compare_ways, format_table, paired_differences
    net = RandomFeatures(sizes=(3, 5), channels=8, scales=2)
    rows = compare_ways(models.teapot(2, dtype=torch.float64), stripes(32, dtype=torch.float64), net, steps=2,
                        size=24, views=1, seeds=1)
    assert sorted((r["run"], r["seed"]) for r in rows) == sorted((w, 0) for w, _ in WAYS)
    assert all(r["outline"] == 0 for r in rows if "texture only" in r["run"])
    assert all(r["held_out"] > 0 and r["held_out_soft"] > 0 for r in rows)
    pairs = paired_differences(rows)
    assert len(pairs) == 2 * len(PAIRS) and all(len(p["diffs"]) == 1 and p["sign"] is None for p in pairs)
    made = [dict(run=w, seed=s, steps=1, seconds=1.0, train=1.0, held_out=1.0 + 0.1 * k + 0.01 * s,
                 held_out_soft=2.0 - 0.1 * k * s, outline=0.0, moved=0.0) for k, (w, _) in enumerate(WAYS)
            for s in range(3)]
    verdicts = {(p["a"], p["b"], p["judge"]): p["sign"] for p in paired_differences(made)}
    assert verdicts["NMR", "z-buffer", "z-buffer judge"] == "lower"         # -0.1 at every seed, spread 0
    assert verdicts["NMR", "z-buffer", "soft judge"] is None                # 0, +0.1, +0.2: mean 0.1, spread 0.2
    table = format_table(made, seconds=False)
    assert "3 seed(s): 0, 1, 2" in table and "no measurable difference" in table and "seconds" not in table


def test_deep_dream_raises_the_activation():
    mesh = models.teapot(2, dtype=torch.float64)
    net = RandomFeatures(sizes=(3, 5), channels=8, scales=2)
    run = deep_dream_mesh(mesh, steps=10, size=32, texture_size=16, network=net, block=1, channels=(0, 1))
    assert run.losses.shape == (10,) and float(run.losses[-1]) > 2 * float(run.losses[0]) > 0
    step = float((run.verts - mesh.verts).norm(dim=1).max())
    assert step <= 10 * 0.05 * math.sqrt(3) * 1.01 / 10 * float(mesh.verts.norm(dim=1).max()) + 1e-12


def test_bad_inputs_are_named():
    mesh = models.teapot(2, dtype=torch.float64)
    with pytest.raises(ValueError, match="uvs"):
        stylize_mesh(Mesh(mesh.verts, mesh.faces), stripes(32), steps=1)
    with pytest.raises(ValueError, match="renderer"):
        stylize_mesh(mesh, stripes(32), steps=1, renderer="ray")
    with pytest.raises(ValueError, match="style"):
        stylize_mesh(mesh, torch.zeros(32, 32), steps=1)
    with pytest.raises(ValueError, match="steps"):
        deep_dream_mesh(mesh, steps=0)
    with pytest.raises(ValueError, match="block"):
        deep_dream_mesh(mesh, steps=1, size=32, block=99)
    with pytest.raises(ValueError, match="channels"):
        deep_dream_mesh(mesh, steps=1, size=32, channels=(100,))
    with pytest.raises(ValueError, match="n"):
        random_directions(0, torch.Generator())
