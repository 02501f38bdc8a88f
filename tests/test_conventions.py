"""The fixed conventions of DESIGN.md, each pinned by one small test.

Pixel centres at half-integers, OpenCV camera axes (+x right, +y down, +z forward), counter-clockwise
front faces, row 0 at the top of the image, top-left fill rule.
"""
import torch

from course.camera import Camera, look_at, pixel_rays
from course.mesh import Mesh
from course.raster import rasterize


def ortho_camera(width=8, height=8):
    """Looks down -z from z = 5; one world unit = one pixel; world (0, 0) at the image centre."""
    return Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=height, width=width, height=height,
                          dtype=torch.float64)


def test_pixel_centres_are_half_integers():
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=8, height=6)
    origins, dirs = cam.rays()
    assert dirs.shape == (6, 8, 3)
    pix, depth = cam.project(origins[0, 0] + 2.0 * dirs[0, 0][None])
    assert torch.allclose(pix, torch.tensor([[0.5, 0.5]]), atol=1e-5)       # pixel (0, 0): centre (0.5, 0.5)
    pix, _ = cam.project(origins[5, 7] + 2.0 * dirs[5, 7][None])
    assert torch.allclose(pix, torch.tensor([[7.5, 5.5]]), atol=1e-5)       # (row 5, col 7): (7.5, 5.5)


def test_camera_axes_are_opencv():
    R, t = look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    assert torch.allclose(R @ torch.tensor([1.0, 0, 0]), torch.tensor([1.0, 0, 0]))  # world +x → right
    assert torch.allclose(R @ torch.tensor([0, 1.0, 0]), torch.tensor([0, -1.0, 0]))  # world up → camera -y
    assert torch.allclose(R @ torch.tensor([0, 0, -1.0]), torch.tensor([0, 0, 1.0]))  # view direction → +z
    assert torch.isclose(torch.linalg.det(R), torch.tensor(1.0))            # right-handed, a rotation
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=8, height=8)
    pix, depth = cam.project(torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]]))
    assert pix[0, 0] > 4 and pix[1, 1] < 4                                  # right is +x, up is -y (row)
    assert torch.allclose(depth, torch.full((3,), 5.0))                     # depth positive in front


def test_row_zero_is_the_top_of_the_image():
    # a triangle above the optical axis (world +y) lands in the top rows
    mesh = Mesh([[-2.0, 1.0, 0.0], [2.0, 1.0, 0.0], [0.0, 3.0, 0.0]], [[0, 1, 2]])
    fr = rasterize(mesh, ortho_camera())
    rows = fr.mask.nonzero()[:, 0]
    assert rows.numel() > 0 and rows.max() < 4


def test_counter_clockwise_faces_front():
    ccw = Mesh([[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [0.0, 3.0, 0.0]], [[0, 1, 2]])  # CCW seen from +z
    cw = Mesh(ccw.verts, [[0, 2, 1]])
    cam = ortho_camera()
    assert rasterize(ccw, cam, cull_backfaces=True).mask.any()
    assert not rasterize(cw, cam, cull_backfaces=True).mask.any()
    assert rasterize(cw, cam).mask.sum() == rasterize(ccw, cam).mask.sum()   # no culling: both drawn
    assert ccw.face_normals()[0, 2] > 0                                      # normal points to the viewer
    persp = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=8, height=8)
    assert rasterize(ccw, persp, cull_backfaces=True).mask.any()
    assert not rasterize(cw, persp, cull_backfaces=True).mask.any()


def test_pixel_covers_unit_square_and_top_left_rule():
    # screen square x in [2, 5], y in [1, 4] (pixel units): pixel centres 2.5, 3.5, 4.5 are inside
    # in x and 1.5, 2.5, 3.5 in y; exact edges through no centre
    cam = ortho_camera()
    to_world = lambda x, y: [x - 4.0, 4.0 - y, 0.0]                         # screen → world for this camera
    quad = Mesh([to_world(2, 1), to_world(2, 4), to_world(5, 4), to_world(5, 1)], [[0, 1, 2], [0, 2, 3]])
    mask = rasterize(quad, cam).mask
    assert mask.nonzero()[:, 0].unique().tolist() == [1, 2, 3]
    assert mask.nonzero()[:, 1].unique().tolist() == [2, 3, 4]
    # edges through pixel centres: x in [1.5, 4.5], y in [0.5, 3.5]; the left and top edges are in, the
    # right and bottom edges out, so centres 1.5..3.5 × 0.5..2.5 → 3 × 3 pixels, never 4 × 4
    quad = Mesh([to_world(1.5, 0.5), to_world(1.5, 3.5), to_world(4.5, 3.5), to_world(4.5, 0.5)],
                [[0, 1, 2], [0, 2, 3]])
    fr = rasterize(quad, cam)
    assert fr.mask.nonzero()[:, 0].unique().tolist() == [0, 1, 2]
    assert fr.mask.nonzero()[:, 1].unique().tolist() == [1, 2, 3]


def test_pixel_rays_match_projection_of_pixel_centres():
    cam = Camera.look_at((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), fov_y=45, width=5, height=4, dtype=torch.float64)
    origins, dirs = pixel_rays(cam.K, cam.R, cam.t, 5, 4)
    pts = (origins + 3.0 * dirs).reshape(-1, 3)
    pix, _ = cam.project(pts)
    rows, cols = torch.meshgrid(torch.arange(4.0), torch.arange(5.0), indexing="ij")
    want = torch.stack([cols.flatten() + 0.5, rows.flatten() + 0.5], 1).double()
    assert torch.allclose(pix, want, atol=1e-9)
