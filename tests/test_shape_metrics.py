"""3D metrics of a fitted mesh (course.inverse.metrics) and Large Steps (course.inverse.large_steps)."""
import math

import pytest
import torch

from course import models
from course.inverse import fit_silhouettes, sphere_views
from course.inverse.large_steps import Parameterization, UniformAdam, laplacian
from course.mesh import Mesh
from course.inverse.metrics import (chamfer_distance, f_score, normal_consistency, sample_surface, shape_metrics,
                                   surface_distance, surface_scores)


def _expected_offset_chamfer(d):
    """Mean distance from a point uniform on the unit sphere to the unit sphere centred d away: with x = cos θ
    uniform in [-1, 1] the point is sqrt(1 + d² - 2 d x) from the other centre (by symmetry the same both ways)."""
    x = torch.linspace(-1, 1, 2_000_001, dtype=torch.float64)
    return float(torch.trapezoid((torch.sqrt(1 + d * d - 2 * d * x) - 1).abs(), x) / 2)


def test_chamfer_of_concentric_and_offset_spheres():
    """Concentric spheres of radii 1 and 1.1: every nearest distance is 0.1 (plus the samples' spacing, tiny
    against it), so the Chamfer distance is 0.1 over the larger sphere's bounding-box diagonal 2.2 √3, to 1%.
    Spheres offset by 0.3: the mean of |√(1 + d² - 2 d x) - 1| over x uniform, 0.1 exactly; to 3% (where the
    spheres cross, nearest samples are a spacing apart, not 0)."""
    a = models.icosphere(5, 1.0, dtype=torch.float64)
    b = Mesh(a.verts * 1.1, a.faces)
    got = chamfer_distance(a, b)
    assert abs(got / (0.1 / (2.2 * math.sqrt(3))) - 1) < 0.01, got
    assert normal_consistency(a, b) > 0.999
    shifted = Mesh(a.verts + torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64), a.faces)
    want = _expected_offset_chamfer(0.3) / (2 * math.sqrt(3))
    assert abs(chamfer_distance(shifted, a) / want - 1) < 0.03


def test_f_score_of_concentric_spheres_and_half_a_sphere():
    """Concentric spheres a gap apart: every point is within the gap of the other surface (the gap along the
    normal is the nearest distance up to the sampling's spacing), so F is 1 for a threshold above it and 0 below.
    A closed sphere against its upper half (a cap, open): precision 1, recall about 1/2, F about 2/3."""
    unit, wider = models.icosphere(3, 1.0, dtype=torch.float64), models.icosphere(3, 1.03, dtype=torch.float64)
    assert f_score(unit, unit, samples=1000) == 1.0
    assert f_score(unit, wider, threshold=0.04, samples=1000) == 1.0
    assert f_score(unit, wider, threshold=0.02, samples=1000) == 0.0
    both = surface_scores(unit, wider, threshold=0.04, samples=1000)             # point to surface: the gap
    diagonal = float((wider.verts.max(0).values - wider.verts.min(0).values).norm())
    assert both["fscore"] == 1.0 and abs(both["chamfer"] * diagonal - 0.03) < 0.003
    keep = unit.verts[unit.faces].mean(1)[:, 1] > 0
    cap = Mesh(unit.verts, unit.faces[keep])
    assert abs(f_score(cap, unit, threshold=0.02, samples=3000) - 2 / 3) < 0.03
    with pytest.raises(ValueError, match="threshold"):
        f_score(unit, unit, threshold=0.0)


def test_surface_distance_is_exact_in_every_region_of_a_triangle():
    """Points over the face, beyond each edge and each vertex, on the triangle, and a degenerate triangle: the
    distance is the hand-computed one, and never above a dense sampling's nearest point."""
    tri = Mesh(torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64), torch.tensor([[0, 1, 2]]))
    p = torch.tensor([[0.2, 0.2, 0.5], [2, 0, 0], [0.5, 0.5, 1], [-1, -1, 0], [0.5, -1, 0], [0.3, 0.3, -0.1],
                      [0.25, 0.25, 0], [0, 3, 4]], dtype=torch.float64)
    expected = torch.tensor([0.5, 1, 1, 2 ** 0.5, 1, 0.1, 0, 20 ** 0.5], dtype=torch.float64)
    torch.testing.assert_close(surface_distance(p, tri), expected, atol=1e-15, rtol=0)
    g = torch.Generator().manual_seed(3)
    for degenerate in (False, True):
        v = torch.randn(3, 3, generator=g, dtype=torch.float64)
        if degenerate:
            v[2] = v[0] + 0.5 * (v[1] - v[0])                                   # a segment
        x = torch.randn(100, 3, generator=g, dtype=torch.float64) * 2
        u = torch.linspace(0, 1, 401, dtype=torch.float64)
        uu, vv = torch.meshgrid(u, u, indexing="ij")
        keep = uu + vv <= 1 + 1e-12
        dense = v[0] + uu[keep, None] * (v[1] - v[0]) + vv[keep, None] * (v[2] - v[0])
        brute = torch.cdist(x, dense).min(1).values
        got = surface_distance(x, Mesh(v, torch.tensor([[0, 1, 2]])))
        assert bool((got <= brute + 1e-14).all()) and float((brute - got).max()) < 5e-4
        hinted = surface_distance(x, Mesh(v, torch.tensor([[0, 1, 2]])), on_surface=dense[::7])
        torch.testing.assert_close(hinted, got, atol=1e-13, rtol=0)           # a point on it: rounding apart


def test_the_grid_search_finds_exactly_the_brute_forces_nearest_samples():
    """Surfaces near each other, far apart, crossing, of different sizes, and point sets with exact ties (a
    lattice and its copy): the same indices (the first of equals) and distances as comparing every pair."""
    from course.inverse.metrics import _nearest, _nearest_brute
    g = torch.Generator().manual_seed(3)
    sphere, _ = sample_surface(models.icosphere(3, 1.0, dtype=torch.float64), 1500, g)
    teapot, _ = sample_surface(models.teapot(3), 1500, g)
    lattice = torch.stack(torch.meshgrid(*[torch.arange(8.0, dtype=torch.float64)] * 3, indexing="ij"), -1)
    lattice = lattice.reshape(-1, 3)
    cases = [(sphere, sphere * 1.01), (sphere, sphere + 5.0), (sphere, teapot), (teapot, sphere * 0.1),
             (lattice, lattice.flip(0)), (lattice + 0.5, lattice), (sphere[:1], teapot), (teapot, sphere[:1])]
    for x, y in cases:
        index, dist = _nearest(x, y)
        want_index, want_squared = _nearest_brute(x, y)
        assert torch.equal(index, want_index) and torch.equal(dist, want_squared.sqrt())
        d = x[:, None, :] - y[None, :, :]                                   # every pair, written out
        squared = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
        first = torch.where(squared == squared.min(1, keepdim=True).values, torch.arange(y.shape[0]), y.shape[0])
        assert torch.equal(want_index, first.min(1).values) and torch.equal(want_squared, squared.min(1).values)


def test_a_cube_against_itself_and_a_crumpled_sphere():
    cube = models.cube(dtype=torch.float64)
    m = shape_metrics(cube, cube, samples=5000)
    assert m["chamfer"] < 1e-9 and abs(m["normal_consistency"] - 1) < 1e-12 and m["self_intersections"] == 0
    sphere = models.icosphere(3, 1.0, dtype=torch.float64)
    g = torch.Generator().manual_seed(0)
    crumpled = Mesh(sphere.verts * (1 + 0.05 * torch.randn(sphere.verts.shape[0], 1, generator=g,
                                                            dtype=torch.float64)), sphere.faces)
    assert normal_consistency(crumpled, sphere) < 0.97 < normal_consistency(sphere, sphere)


def test_surface_samples_are_uniform_by_area():
    """Two triangles of areas 1/2 and 3/2 side by side in the plane z = 0: a quarter of the samples in the
    first (5 standard errors), their mean at the area centroid, normals +z."""
    v = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 3.0, 0.0]], dtype=torch.float64)
    mesh = Mesh(v, torch.tensor([[0, 1, 2], [1, 3, 2]]))
    p, n = sample_surface(mesh, 40000, torch.Generator().manual_seed(1))
    first = float((p[:, 0] + p[:, 1] < 1).double().mean())
    assert abs(first - 0.25) < 5 * math.sqrt(0.25 * 0.75 / 40000)
    centroid = (0.5 * v[[0, 1, 2]].mean(0) + 1.5 * v[[1, 3, 2]].mean(0)) / 2
    assert float((p.mean(0) - centroid).norm()) < 0.02
    assert torch.allclose(n, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand_as(n))
    with pytest.raises(ValueError, match="area"):
        sample_surface(Mesh(torch.zeros(3, 3), torch.tensor([[0, 1, 2]])), 10)
    with pytest.raises(ValueError, match="faces"):
        sample_surface(Mesh(v, torch.tensor([[0, 1, 9]])), 10)


def test_the_preconditioned_gradient_is_a_dense_solve():
    """u = (I + λL) v: v comes back from u, and the gradient reaching u is (I + λL)⁻¹ times the gradient at v,
    checked against torch.linalg.solve on a small mesh; λ = 0 is the identity."""
    mesh = models.icosphere(2, 0.5, dtype=torch.float64)
    V = mesh.verts.shape[0]
    L = laplacian(mesh.faces, V)
    assert torch.equal(L, L.T) and float(L.sum(1).abs().max()) == 0 and int(L.diagonal().min()) == 5
    p = Parameterization(mesh.verts, mesh.faces, lam=10.0)
    v = p.verts()
    assert float((v.detach() - mesh.verts).abs().max()) < 1e-12
    g = torch.randn(V, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    (v * g).sum().backward()
    want = torch.linalg.solve(torch.eye(V, dtype=torch.float64) + 10.0 * L, g)
    assert float((p.u.grad - want).abs().max()) < 1e-12
    u = p.u.detach().clone().requires_grad_(True)                   # the two triangular solves are potrs,
    reference = torch.cholesky_solve(u, p.factor)[p.weld]          # bit for bit, both ways
    (reference * g).sum().backward()
    assert torch.equal(reference.detach(), v.detach()) and torch.equal(u.grad, p.u.grad)
    identity = Parameterization(mesh.verts, mesh.faces, lam=0.0)
    assert torch.equal(identity.u.detach(), mesh.verts)
    with pytest.raises(ValueError, match="lam"):
        Parameterization(mesh.verts, mesh.faces, lam=-1.0)


def test_seam_copies_are_one_unknown():
    teapot = models.teapot(3, dtype=torch.float64)
    p = Parameterization(teapot.verts, teapot.faces, lam=5.0)
    assert p.u.shape[0] < teapot.verts.shape[0]                            # the seams' copies welded
    with torch.no_grad():
        p.u += torch.randn(p.u.shape, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    v = p.verts()
    from course.boundary import _weld
    weld = _weld(teapot.verts)
    first = torch.zeros(int(weld.max()) + 1, dtype=torch.long).scatter_(0, weld, torch.arange(weld.numel()))
    assert torch.equal(v, v[first][weld])                                  # copies moved together


def test_uniform_adam_steps_every_entry_by_one_scale():
    """First step: m̂ = g, v̂ = g², so the step is lr · g / max |g| (Adam's own would be lr · sign g)."""
    x = torch.zeros(4, dtype=torch.float64, requires_grad=True)
    opt = UniformAdam([x], lr=0.1)
    g = torch.tensor([1.0, -2.0, 4.0, 0.5], dtype=torch.float64)
    (x * g).sum().backward()
    opt.step()
    assert torch.allclose(x.detach(), -0.1 * g / 4, rtol=0, atol=1e-9)


def test_large_steps_fit_keeps_the_surface_clean():
    """A short silhouette fit with Large Steps improves the held-out IoU and crosses no faces."""
    teapot = models.teapot(3, dtype=torch.float64)
    cams = sphere_views(4, size=32, offset=1.9, dtype=torch.float64)
    fit = fit_silhouettes(teapot, cams, steps=30, optimizer="large_steps", lr=0.02, lam=5.0, smoothness=0.0,
                          subdivisions=2, held_out=sphere_views(8, size=32, dtype=torch.float64),
                          snapshot_every=None, progress=False)
    assert fit.iou > fit.start_iou + 0.05 and shape_metrics(fit.mesh, teapot, samples=4000)["self_intersections"] == 0
    with pytest.raises(ValueError, match="optimizer"):
        fit_silhouettes(teapot, cams, steps=1, optimizer="sgd", progress=False)
