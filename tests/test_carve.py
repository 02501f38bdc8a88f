"""The visual hull (course.inverse.carve): surface nets on analytic fields, carving a sphere and a torus, bad input."""
import math

import pytest
import torch

from course import models
from course.inverse import carve
from course.camera import Camera
from course.inverse import coverage_masks, sphere_views
from course.mesh import Mesh
from course.inverse.metrics import chamfer_distance


def _topology(mesh):
    """(faces per undirected edge, counts of repeated directed edges, Euler characteristic, signed volume)."""
    f = mesh.faces
    directed = torch.cat([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    undirected, per_edge = torch.unique(torch.sort(directed, 1).values, dim=0, return_counts=True)
    _, repeats = torch.unique(directed, dim=0, return_counts=True)
    v = mesh.verts.double()
    volume = float((v[f[:, 0]] * torch.linalg.cross(v[f[:, 1]], v[f[:, 2]], dim=-1)).sum() / 6)
    chi = v.shape[0] - undirected.shape[0] + f.shape[0]
    return per_edge, repeats, chi, volume


def _closed_and_outward(mesh):
    per_edge, repeats, chi, volume = _topology(mesh)
    assert bool((per_edge == 2).all()), torch.bincount(per_edge)           # every edge has two faces
    assert bool((repeats == 1).all())                                      # wound consistently
    assert volume > 0                                                      # outward
    return chi, volume


def _ball(n, radius, r0, center=(0.0, 0.0, 0.0)):
    axis = torch.linspace(-radius, radius, n, dtype=torch.float64)
    x = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), -1)
    return r0 - (x - torch.tensor(center, dtype=torch.float64)).norm(dim=-1)


def test_surface_nets_of_a_ball_is_a_closed_sphere_of_its_radius():
    """The field r0 - |x| on a 33³ grid over [-1, 1]³: the mesh is closed, outward, of genus 0, its vertices lie
    within a tenth of a cell of the sphere (linear interpolation on a smooth field), its volume within 2% of
    4/3 π r0³ (the flat facets cut the sphere a little)."""
    mesh = carve.surface_nets(_ball(33, 1.0, 0.6), 1.0, level=0.0)
    chi, volume = _closed_and_outward(mesh)
    assert chi == 2
    cell = 2 / 32
    assert float((mesh.verts.norm(dim=1) - 0.6).abs().max()) < 0.1 * cell
    assert abs(volume / (4 / 3 * math.pi * 0.6 ** 3) - 1) < 0.02


def test_surface_nets_joins_solids_touching_along_one_grid_edge():
    """Two cubes of grid points that share one grid edge only: without joining, four faces meet at the mesh
    edges there. Joined, every edge has two faces, and the solid is one piece of genus 0."""
    field = -torch.ones(8, 8, 8, dtype=torch.float64)
    field[1:4, 1:4, 1:6] = 1.0
    field[4:7, 4:7, 1:6] = 1.0                                              # touches the first along x = 3.5, y = 3.5
    mesh = carve.surface_nets(field, 1.0, level=0.0)
    chi, _ = _closed_and_outward(mesh)
    assert chi == 2


def test_surface_nets_level_and_bad_input():
    field = _ball(17, 1.0, 0.5)
    big = carve.surface_nets(field, 1.0, level=-0.2)                        # a lower level: a larger ball
    assert float(big.verts.norm(dim=1).mean()) == pytest.approx(0.7, abs=0.02)
    with pytest.raises(ValueError, match="nothing to mesh"):
        carve.surface_nets(field, 1.0, level=2.0)
    with pytest.raises(ValueError, match="cubic grid"):
        carve.surface_nets(field[:, :, :5], 1.0)
    with pytest.raises(ValueError, match="NaN"):
        carve.surface_nets(torch.full((4, 4, 4), float("nan")), 1.0)
    with pytest.raises(ValueError, match="radius"):
        carve.surface_nets(field, 0.0)


def test_relax_lifts_flat_triangles_and_keeps_the_shape():
    mesh = carve.surface_nets(_ball(25, 1.0, 0.6), 1.0, level=0.0)
    smooth = carve.relax(mesh, 2)
    area = lambda m: torch.linalg.cross(m.verts[m.faces[:, 1]] - m.verts[m.faces[:, 0]],  # noqa: E731
                                        m.verts[m.faces[:, 2]] - m.verts[m.faces[:, 0]], dim=-1).norm(dim=1)
    assert float(area(smooth).min()) > float(area(mesh).min())
    assert float((smooth.verts.norm(dim=1) - 0.6).abs().max()) < 0.25 * 2 / 24   # Taubin: no shrinking
    assert torch.equal(carve.relax(mesh, 0).verts, mesh.verts)


def test_carving_a_sphere_gives_its_hull_and_a_torus_keeps_its_hole():
    """A sphere seen from 12 views: the hull is the sphere within 1% of the diagonal, genus 0. A torus lying
    flat, seen from views spread over the sphere (some look through its hole): the hull has genus 1 (χ = 0)."""
    views = sphere_views(12, offset=1.9, size=48, dtype=torch.float64)
    ball = models.icosphere(4, 0.6, dtype=torch.float64)
    hull = carve.carve(coverage_masks(ball, views), views, 40)
    chi, _ = _closed_and_outward(hull)
    assert chi == 2
    assert chamfer_distance(hull, ball, samples=4000) < 0.01
    ring = models.torus(0.6, 0.2, dtype=torch.float64)
    chi, _ = _closed_and_outward(carve.carve(coverage_masks(ring, views), views, 40))
    assert chi == 0


def test_view_radius_and_bad_masks():
    views = sphere_views(4, size=16, dtype=torch.float64)
    assert carve.view_radius(views) == pytest.approx(3 * math.sin(math.radians(20)), rel=1e-9)
    masks = torch.zeros(4, 16, 16, dtype=torch.float64)
    with pytest.raises(ValueError, match="one per camera"):
        carve.hull_field(masks[:3], views)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        carve.hull_field(masks + 2, views)
    with pytest.raises(ValueError, match="renders"):
        carve.hull_field(torch.zeros(4, 8, 8), views)
    with pytest.raises(ValueError, match="non-empty list of Camera"):
        carve.hull_field(masks, [])
    ortho = Camera(views[0].K, views[0].R, views[0].t, 16, 16, orthographic=True)
    with pytest.raises(ValueError, match="perspective"):
        carve.hull_field(masks[:1], [ortho])
    with pytest.raises(ValueError, match="nothing to mesh"):
        carve.carve(masks, views, 8)
    assert isinstance(carve.carve(masks + 1, views, 8), Mesh)               # all inside: the grid's cube
