"""Tests for course.inverse.losses: each loss against hand-computed values on tiny inputs, gradcheck in float64,
finite values and gradients for empty silhouettes and degenerate faces, and clear errors for bad inputs."""
import math

import numpy as np
import pytest
import torch

from course.inverse.losses import (edge_length_loss, interior_edges, iou, l1_loss, l2_loss, laplacian_loss, psnr,
                           silhouette_iou_loss, smoothness_loss)
from course.mesh import Mesh
from course.models import cube, icosphere, plane

DTYPES = [torch.float32, torch.float64]

# regular tetrahedron around the origin, circumradius sqrt(3), faces counter-clockwise from outside
TETRA_VERTS = [[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
TETRA_FACES = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]


def folded_pair(phi: float, dtype=torch.float64):
    """Two triangles sharing the edge (0,0,0)-(1,0,0); the second turned by phi about it.

    The first lies in the xy-plane with normal +z; the second starts flat (phi = 0) on the other side of the
    edge and is rotated about the x-axis by phi, so the angle between the normals is phi."""
    verts = torch.tensor([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -math.cos(phi), -math.sin(phi)]], dtype=dtype)
    return verts, torch.tensor([[0, 1, 2], [1, 0, 3]])


def bumpy_sphere(dtype=torch.float64, seed=0):
    """(V, 3) verts and (F, 3) faces of an icosphere with every vertex moved a little, at random."""
    sphere = icosphere(1, dtype=dtype)
    g = torch.Generator().manual_seed(seed)
    return sphere.verts + 0.05 * torch.randn(sphere.verts.shape, generator=g, dtype=dtype), sphere.faces


def square(rows, cols, size=8, dtype=torch.float64):
    """(size, size) mask, 1 on the given row and column slices."""
    mask = torch.zeros(size, size, dtype=dtype)
    mask[rows, cols] = 1
    return mask


# ---- silhouettes -----------------------------------------------------------------------------
def test_silhouette_loss_by_hand():
    pred = torch.tensor([[1.0, 0.5], [0.0, 0.0]], dtype=torch.float64)
    target = torch.tensor([[1.0, 0.0], [1.0, 0.0]], dtype=torch.float64)
    # intersection 1, union (1 + 1 - 1) + 0.5 + 1 = 2.5
    assert silhouette_iou_loss(pred, target).item() == pytest.approx(1 - 1 / 2.5)
    assert silhouette_iou_loss(target, target).item() == 0.0


def test_silhouette_loss_sums_over_views():
    a, b = square(slice(0, 4), slice(0, 4)), square(slice(2, 6), slice(2, 6))  # overlap 4 of union 28
    views_pred, views_target = torch.stack([a, a]), torch.stack([a, b])
    assert silhouette_iou_loss(views_pred, views_target).item() == pytest.approx(1 - 4 / 28)
    assert silhouette_iou_loss(views_pred, views_target, reduction="mean").item() == pytest.approx((1 - 4 / 28) / 2)
    per_view = silhouette_iou_loss(views_pred, views_target, reduction="none")
    assert per_view.shape == (2,) and torch.allclose(per_view, torch.tensor([0, 1 - 4 / 28], dtype=torch.float64))


def test_silhouette_loss_empty_is_defined():
    empty = torch.zeros(4, 4, dtype=torch.float64, requires_grad=True)
    loss = silhouette_iou_loss(empty, torch.zeros(4, 4))
    loss.backward()
    assert loss.item() == 0.0 and torch.isfinite(empty.grad).all()          # both empty: 0 by convention
    empty.grad = None
    loss = silhouette_iou_loss(empty, square(slice(0, 2), slice(0, 2), size=4))
    loss.backward()
    assert loss.item() == 1.0 and torch.isfinite(empty.grad).all()          # nothing of the target covered
    assert (empty.grad < 0).any()                                           # and covering it would help


def test_silhouette_loss_gradcheck():
    g = torch.Generator().manual_seed(1)
    pred = (0.1 + 0.8 * torch.rand(2, 5, 6, generator=g, dtype=torch.float64)).requires_grad_()
    target = torch.rand(2, 5, 6, generator=g, dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda p: silhouette_iou_loss(p, target), (pred,))


def test_iou_of_two_squares():
    a, b = square(slice(0, 4), slice(0, 4)), square(slice(2, 6), slice(2, 6))
    assert iou(a, b).item() == pytest.approx(4 / 28)
    assert iou(a, a).item() == 1.0
    assert iou(a.bool(), b.bool()).item() == pytest.approx(4 / 28)           # bools work too
    assert iou(0.5 * a, a).item() == 0.0                                   # 0.5 is not above the threshold
    assert iou(0.6 * a, a).item() == 1.0
    assert iou(torch.zeros(3, 3), torch.zeros(3, 3)).item() == 1.0         # both empty
    per_view = iou(torch.stack([a, a]), torch.stack([a, b]))
    assert per_view.shape == (2,) and torch.allclose(per_view, torch.tensor([1, 4 / 28], dtype=torch.float64))


# ---- smoothness ------------------------------------------------------------------------------
@pytest.mark.parametrize("phi_degrees", [0, 30, 60, 90, 150])
def test_smoothness_of_a_folded_pair(phi_degrees):
    phi = math.radians(phi_degrees)
    verts, faces = folded_pair(phi)
    assert smoothness_loss(verts, faces).item() == pytest.approx((1 - math.cos(phi)) ** 2, abs=1e-12)
    assert smoothness_loss(Mesh(verts, faces)).item() == pytest.approx((1 - math.cos(phi)) ** 2, abs=1e-12)


def test_smoothness_of_known_shapes():
    assert smoothness_loss(plane(subdivisions=3, dtype=torch.float64)).item() == pytest.approx(0, abs=1e-12)
    # cube: 6 flat diagonals (0) and 12 edges where the normals meet at 90 degrees (1 each)
    assert smoothness_loss(cube(dtype=torch.float64)).item() == pytest.approx(12)
    # regular tetrahedron: neighbouring normals have n1.n2 = -1/3, so 6 edges of (4/3)^2
    assert smoothness_loss(TETRA_VERTS, TETRA_FACES).item() == pytest.approx(6 * 16 / 9)


def test_interior_edges_use_connectivity_not_positions():
    edges, pairs = interior_edges(torch.tensor([[0, 1, 2], [1, 0, 3], [1, 3, 4]]))
    assert sorted(map(tuple, edges.tolist())) == [(0, 1), (1, 3)]
    assert sorted(map(sorted, pairs.tolist())) == [[0, 1], [1, 2]]
    # the same two triangles with the shared edge's vertices duplicated: no interior edge, nothing to smooth
    verts, _ = folded_pair(math.radians(90))
    split = torch.cat([verts, verts[:2]])
    assert interior_edges([[0, 1, 2], [5, 4, 3]])[0].shape == (0, 2)
    assert smoothness_loss(split, [[0, 1, 2], [5, 4, 3]]).item() == 0.0
    assert interior_edges([[0, 1, 2], [1, 0, 3], [0, 1, 4]])[0].shape == (0, 2)  # three faces on one edge


def test_smoothness_degenerate_face_is_finite():
    verts, faces = folded_pair(math.radians(40))
    verts = verts.clone()
    verts[3] = torch.tensor([0.5, 0.0, 0.0], dtype=torch.float64)          # on the shared edge: zero area
    verts.requires_grad_()
    loss = smoothness_loss(verts, faces)
    loss.backward()
    assert loss.item() == pytest.approx(1.0)                               # zero normal: the edge adds 1
    assert torch.isfinite(verts.grad).all()


def test_smoothness_gradcheck():
    verts, faces = bumpy_sphere()
    assert torch.autograd.gradcheck(lambda v: smoothness_loss(v, faces), (verts.requires_grad_(),))


# ---- Laplacian and edge length ---------------------------------------------------------------
@pytest.mark.parametrize("weights", ["uniform", "cotangent"])
def test_laplacian_of_a_regular_tetrahedron(weights):
    # each vertex sees the other three equally (all angles 60 degrees): delta = mean(others) - v = -4/3 v,
    # and |v|^2 = 3, so |delta|^2 = 16/9 * 3 = 16/3 at every vertex
    assert laplacian_loss(TETRA_VERTS, TETRA_FACES, weights=weights).item() == pytest.approx(16 / 3)


def test_laplacian_of_single_triangles_by_hand():
    right = [[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]
    # uniform: delta0 = (.5, .5) -> .5; delta1 = (-1, .5) -> 1.25; delta2 likewise -> 1.25; mean 1
    assert laplacian_loss(right, [[0, 1, 2]]).item() == pytest.approx(1.0)
    # cotangent: angles 90, 45, 45 -> w12 = 0, w02 = w01 = 1/2; |delta|^2 = .5, 1, 1; mean 5/6
    assert laplacian_loss(right, [[0, 1, 2]], weights="cotangent").item() == pytest.approx(5 / 6)
    # obtuse at vertex 2 (cot < 0, clamped to 0): w01 = 0, w02 = w12 = cot(atan(1/2)) / 2 = 1
    # delta0 = (1, .5) -> 1.25; delta1 = (-1, .5) -> 1.25; delta2 = (0, -.5) -> .25; mean 11/12
    obtuse = [[0.0, 0, 0], [2, 0, 0], [1, 0.5, 0]]
    assert laplacian_loss(obtuse, [[0, 1, 2]], weights="cotangent").item() == pytest.approx(11 / 12)


@pytest.mark.parametrize("weights", ["uniform", "cotangent"])
def test_laplacian_degenerate_faces_are_finite(weights):
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=torch.float64)
    faces = [[0, 1, 2], [0, 3, 1], [0, 2, 4]]                                # collinear, and two corners at one point
    verts.requires_grad_()
    loss = laplacian_loss(verts, faces, weights=weights)
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(verts.grad).all()


@pytest.mark.parametrize("weights", ["uniform", "cotangent"])
def test_laplacian_gradcheck(weights):
    verts, faces = bumpy_sphere()
    assert torch.autograd.gradcheck(lambda v: laplacian_loss(v, faces, weights=weights), (verts.requires_grad_(),))


def test_edge_length_by_hand():
    triangle = [[0.0, 0, 0], [3, 0, 0], [0, 4, 0]]                          # sides 3, 4, 5
    assert edge_length_loss(triangle, [[0, 1, 2]]).item() == pytest.approx(2 / 3)   # variance around 4
    assert edge_length_loss(triangle, [[0, 1, 2]], target_length=5).item() == pytest.approx(5 / 3)
    assert edge_length_loss(TETRA_VERTS, TETRA_FACES).item() == pytest.approx(0, abs=1e-12)
    # a shared edge counts once: square of side 1 split along its diagonal -> lengths 1, 1, 1, 1, sqrt 2
    square_verts = [[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    lengths = torch.tensor([1, 1, 1, 1, math.sqrt(2)], dtype=torch.float64)
    expected = ((lengths - lengths.mean()) ** 2).mean().item()
    assert edge_length_loss(square_verts, [[0, 1, 2], [0, 2, 3]]).item() == pytest.approx(expected)


def test_edge_length_zero_edge_and_gradcheck():
    verts = torch.tensor([[0.0, 0, 0], [0, 0, 0], [0, 1, 0]], dtype=torch.float64, requires_grad=True)
    loss = edge_length_loss(verts, [[0, 1, 2]])
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(verts.grad).all()
    bumpy, faces = bumpy_sphere()
    for target_length in (None, 0.5):
        assert torch.autograd.gradcheck(lambda v: edge_length_loss(v, faces, target_length), (bumpy.requires_grad_(),))


# ---- images ----------------------------------------------------------------------------------
def test_image_losses_by_hand():
    pred = torch.tensor([[[0.0, 0.5], [1.0, 1.0]]], dtype=torch.float64)    # (1, 2, 2)
    target = torch.tensor([[[0.5, 0.5], [0.0, 1.0]]], dtype=torch.float64)
    assert l1_loss(pred, target).item() == pytest.approx((0.5 + 1.0) / 4)
    assert l2_loss(pred, target).item() == pytest.approx((0.25 + 1.0) / 4)


def test_psnr_by_hand_and_with_a_mask():
    target = torch.zeros(4, 4, 3, dtype=torch.float64)
    assert psnr(target + 0.1, target).item() == pytest.approx(20.0)          # MSE 0.01
    assert psnr(target, target).item() == math.inf                          # identical images
    pred = target.clone()
    pred[:2, :2] = 0.1                                                      # the object: 4 of 16 pixels
    mask = torch.zeros(4, 4, dtype=torch.bool)
    mask[:2, :2] = True
    assert psnr(pred, target, mask=mask).item() == pytest.approx(20.0)
    assert psnr(pred, target).item() == pytest.approx(20.0 + 10 * math.log10(4))  # background dilutes the MSE
    assert psnr(pred[None], target[None], mask=mask[None].double()).item() == pytest.approx(20.0)
    with pytest.raises(ValueError, match="mask selects no pixel"):
        psnr(pred, target, mask=torch.zeros(4, 4, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"mask must have the image's shape without channels, \(4, 4\)"):
        psnr(pred, target, mask=mask[:3])


def test_image_losses_gradcheck():
    g = torch.Generator().manual_seed(2)
    pred = torch.rand(3, 4, 3, generator=g, dtype=torch.float64, requires_grad=True)
    target = torch.rand(3, 4, 3, generator=g, dtype=torch.float64)
    mask = torch.rand(3, 4, generator=g) > 0.5
    for loss in (l1_loss, l2_loss, psnr, lambda p, t: psnr(p, t, mask=mask)):
        assert torch.autograd.gradcheck(lambda p: loss(p, target), (pred,))


# ---- dtypes, inputs and errors ---------------------------------------------------------------
@pytest.mark.parametrize("dtype", DTYPES)
def test_dtype_is_kept(dtype):
    sil = square(slice(0, 4), slice(0, 4), dtype=dtype)
    image = torch.rand(4, 4, 3, dtype=dtype)
    verts, faces = bumpy_sphere(dtype)
    results = [silhouette_iou_loss(sil, sil.double()), iou(sil, sil), l1_loss(image, image.double()),
               l2_loss(image, image), psnr(image, image * 0.5), smoothness_loss(verts, faces),
               laplacian_loss(verts, faces), laplacian_loss(verts, faces, weights="cotangent"),
               edge_length_loss(verts, faces)]
    assert all(r.dtype == dtype for r in results)
    float64 = [silhouette_iou_loss(sil.double(), sil.double()), smoothness_loss(verts.double(), faces),
               laplacian_loss(verts.double(), faces, weights="cotangent"), edge_length_loss(verts.double(), faces)]
    for low, high in zip(results[:1] + results[5:6] + results[7:], float64):
        assert low.item() == pytest.approx(high.item(), rel=1e-5, abs=1e-6)


def test_numpy_and_lists_are_accepted():
    sil = np.zeros((4, 4))
    sil[1:3, 1:3] = 1
    assert silhouette_iou_loss(sil, sil).item() == 0.0
    assert smoothness_loss(np.array(TETRA_VERTS), np.array(TETRA_FACES)).item() == pytest.approx(32 / 3)


@pytest.mark.parametrize("call, message", [
    (lambda: silhouette_iou_loss(torch.zeros(4), torch.zeros(4)), r"pred must be an \(H, W\) silhouette"),
    (lambda: silhouette_iou_loss(torch.zeros(4, 4), torch.zeros(4, 5)), "same shape, got \\(4, 4\\) and \\(4, 5\\)"),
    (lambda: silhouette_iou_loss(torch.full((2, 2), math.nan), torch.zeros(2, 2)), "pred contains NaN"),
    (lambda: silhouette_iou_loss(torch.zeros(2, 2), torch.full((2, 2), 2.0)), r"target must hold coverage in \[0, 1\]"),
    (lambda: silhouette_iou_loss(torch.zeros(2, 2), torch.zeros(2, 2), reduction="max"), "reduction must be"),
    (lambda: iou(torch.zeros(1, 2, 2, 2), torch.zeros(1, 2, 2, 2)), "pred must be an"),
    (lambda: smoothness_loss(torch.zeros(4, 2), TETRA_FACES), r"verts must have shape \(V, 3\)"),
    (lambda: smoothness_loss(TETRA_VERTS, [[0, 1, 2, 3]]), r"faces must have shape \(F, 3\)"),
    (lambda: smoothness_loss(TETRA_VERTS, [[0, 1, 7]]), "faces index vertex 7 but the mesh has 4 vertices"),
    (lambda: smoothness_loss([[math.nan, 0, 0]] + TETRA_VERTS[1:], TETRA_FACES), "NaN"),
    (lambda: smoothness_loss(TETRA_VERTS), "faces is missing"),
    (lambda: smoothness_loss(Mesh(TETRA_VERTS, TETRA_FACES), TETRA_FACES), "either a Mesh or verts and faces"),
    (lambda: laplacian_loss(TETRA_VERTS, TETRA_FACES, weights="cot"), 'weights must be "uniform" or "cotangent"'),
    (lambda: edge_length_loss(torch.zeros(3, 3, 1), [[0, 1, 2]]), r"verts must have shape \(V, 3\)"),
    (lambda: interior_edges([[0.0, 1, 2]]), r"faces must be \(F, 3\) integer"),
    (lambda: l1_loss(torch.zeros(2, 2, 3), torch.zeros(2, 2, 4)), "same shape"),
    (lambda: l2_loss(torch.zeros(2, 2, 3), torch.full((2, 2, 3), math.inf)), "target contains NaN or inf"),
    (lambda: psnr(torch.zeros(2, 2), torch.zeros(2, 2)), r"pred must be an \(H, W, C\) image"),
])
def test_bad_inputs_raise_clear_errors(call, message):
    with pytest.raises(ValueError, match=message):
        call()
