"""The exact form factor of a partly hidden polygonal light (course.shadows.area.light_form_factor): against Monte
Carlo shadow rays traced with the course's BVH (10⁶ samples a point, within 3 standard errors), and its gradient
against converged float64 central differences, on scenes beyond the easy ones: an occluder edge parallel to a
light edge, overlapping occluders, an occluder touching the receiver, a light seen edge-on, receiver points on
the umbra's and the penumbra's boundaries, float32 inputs."""
import math

import pytest
import torch

from course.bvh import BVH
from course.mesh import Mesh
from course.raytrace import visible
from course.shadows.area import light_form_factor

F64 = torch.float64


def square_light(half=0.5, height=2.0, centre=(0.0, 0.0)):
    """A square light in the plane y = height, facing down (-y): counter-clockwise about -y."""
    cx, cz = centre
    v = [[cx - half, height, cz - half], [cx + half, height, cz - half], [cx + half, height, cz + half],
         [cx - half, height, cz + half]]
    return torch.tensor(v, dtype=F64)                                       # normal: (e1 × e2) points to -y


def occluder(*tris):
    verts = torch.tensor([p for t in tris for p in t], dtype=F64)
    return Mesh(verts, torch.arange(verts.shape[0]).view(-1, 3))


SCENES = {
    # one triangle half over the light: points in umbra, penumbra and full light
    "one": (square_light(), occluder([[-1.0, 1.0, -1.0], [0.1, 1.0, -1.0], [0.1, 1.0, 1.0]])),
    # an occluder edge parallel to a light edge (x = 0.2, as the light's edges x = ±0.5)
    "parallel": (square_light(), occluder([[0.2, 1.2, -1.0], [0.2, 1.2, 1.0], [1.5, 1.2, 0.0]])),
    # two overlapping occluders at different heights: each part of the light hidden once
    "overlap": (square_light(), occluder([[-1.0, 1.0, -0.8], [0.3, 1.0, -0.8], [-0.2, 1.0, 0.9]],
                                         [[-0.3, 1.5, -0.6], [0.6, 1.5, -0.5], [0.1, 1.5, 0.7]])),
    # a wall standing on the receiver plane y = 0 (touching it)
    "touching": (square_light(), occluder([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 1.5, 0.0]])),
}
POINTS = torch.tensor([[0.013, 0.0, 0.0], [0.3, 0.0, 0.2], [-0.4, 0.0, -0.1], [0.7, 0.0, -0.3], [-0.2, 0.0, 0.6]],
                      dtype=F64)                                            # (the first: 0.013 from the wall's foot)
UP = torch.tensor([0.0, 1.0, 0.0], dtype=F64)


def monte_carlo(points, normals, light, mesh, samples=1_000_000, seed=0):
    """F by shadow rays: uniform points on the light (two triangles of the fan), weight cosθ cosθ' / (π r²) × area,
    each ray tested against the occluders with the course's BVH. Returns (mean, standard error) per point."""
    g = torch.Generator().manual_seed(seed)
    a, b, c, d = light
    area1 = torch.linalg.cross(b - a, c - a).norm() / 2
    area2 = torch.linalg.cross(c - a, d - a).norm() / 2
    n_l = torch.linalg.cross(b - a, c - a)
    n_l = n_l / n_l.norm()
    means, errors = [], []
    bvh = None if mesh is None else BVH(mesh)
    for x, n in zip(points, normals / normals.norm(dim=1, keepdim=True)):
        u = torch.rand(samples, 2, generator=g, dtype=F64)
        flip = u.sum(1) > 1
        u = torch.where(flip[:, None], 1 - u, u)
        first = torch.rand(samples, generator=g, dtype=F64) < area1 / (area1 + area2)
        p0, p1, p2 = (torch.where(first[:, None], a, a), torch.where(first[:, None], b, c),
                      torch.where(first[:, None], c, d))
        y = p0 + u[:, :1] * (p1 - p0) + u[:, 1:] * (p2 - p0)
        r = y - x
        dist2 = (r * r).sum(1)
        cos_x = (r @ n) / dist2.sqrt()
        cos_l = -(r @ n_l) / dist2.sqrt()
        w = (cos_x.clamp(min=0) * cos_l.clamp(min=0) / (math.pi * dist2)) * (area1 + area2)
        if bvh is not None:
            w = w * visible(x.expand(samples, 3), y, bvh, offset=1e-12).to(F64)
        means.append(float(w.mean()))
        errors.append(float(w.std() / math.sqrt(samples)))
    return torch.tensor(means, dtype=F64), torch.tensor(errors, dtype=F64)


@pytest.mark.parametrize("name", list(SCENES))
def test_the_form_factor_is_what_shadow_rays_converge_to(name):
    light, mesh = SCENES[name]
    normals = UP.expand_as(POINTS)
    exact = light_form_factor(POINTS, normals, light, mesh)
    mc, se = monte_carlo(POINTS, normals, light, mesh)
    assert bool(((exact - mc).abs() <= 3 * se + 1e-12).all()), (exact, mc, se)
    unlit = light_form_factor(POINTS, normals, light)
    assert bool((exact <= unlit + 1e-15).all())                            # occluders only take light away
    if name != "touching":
        assert bool(((exact > 1e-3) & (exact < unlit - 1e-3)).any())        # a penumbra point is among them


def test_tilted_receivers_and_a_light_seen_edge_on():
    """Receivers tilted against the light (the light clipped by their tangent plane); a point in the light's own
    plane (seen edge-on: 0) and just below it; a point above the light (behind it: 0)."""
    light, mesh = SCENES["one"]
    pts = torch.tensor([[0.2, 0.0, 0.1], [0.9, 0.5, 0.0], [2.0, 2.0, 0.0], [2.0, 1.999, 0.0], [0.0, 3.0, 0.0]],
                       dtype=F64)
    nrm = torch.tensor([[1.0, 1.0, 0.0], [-1.0, 0.3, 0.2], [-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]],
                       dtype=F64)
    exact = light_form_factor(pts, nrm, light, mesh)
    assert float(exact[2]) == 0 and float(exact[4]) == 0
    assert 0 < float(exact[3]) < 1e-4
    mc, se = monte_carlo(pts[:4], nrm[:4], light, mesh)
    assert bool(((exact[:4] - mc).abs() <= 3 * se + 1e-12).all()), (exact, mc, se)


def _fd(f, x, h):
    g = torch.zeros_like(x)
    for k in range(x.numel()):
        e = torch.zeros_like(x).view(-1)
        e[k] = h
        e = e.view_as(x)
        g.view(-1)[k] = (f(x + e) - f(x - e)) / (2 * h)
    return g


@pytest.mark.parametrize("name", list(SCENES))
def test_the_gradient_is_the_derivative(name):
    """Autograd through the clipping and Lambert's formula against float64 central differences shown converged
    (steps 1e-5 and 1e-6 agree), w.r.t. the points, the normals, the light's and the occluders' vertices."""
    light, mesh = SCENES[name]
    pts = POINTS[1:4] + torch.tensor([0.013, 0.0, -0.007], dtype=F64)      # off any symmetry
    nrm = UP.expand_as(pts) + torch.tensor([0.05, 0.0, -0.03], dtype=F64)
    ov = mesh.verts.clone()
    leaves = [pts.clone().requires_grad_(), nrm.clone().requires_grad_(), light.clone().requires_grad_(),
              ov.clone().requires_grad_()]
    total = light_form_factor(leaves[0], leaves[1], leaves[2], Mesh(leaves[3], mesh.faces)).sum()
    grads = torch.autograd.grad(total, leaves)
    base = [pts, nrm, light, ov]
    for k, g in enumerate(grads):
        def f(v, k=k):
            args = list(base)
            args[k] = v
            return light_form_factor(args[0], args[1], args[2], Mesh(args[3], mesh.faces)).sum()
        fd5, fd6 = _fd(f, base[k], 1e-5), _fd(f, base[k], 1e-6)
        scale = float(fd6.abs().max()) + 1e-12
        assert float((fd5 - fd6).abs().max()) < 1e-5 * max(scale, 1.0)     # converged
        assert float((g - fd6).abs().max()) < 1e-6 * max(scale, 1.0), (name, k, g, fd6)
    assert float(sum(g.abs().sum() for g in grads[3:])) > 0 or name == "touching"


def test_umbra_and_penumbra_boundaries():
    """Along a line across the shadow of the occluder edge x = 0.1 (height 1) of a light x ∈ [-0.5, 0.5] at height 2,
    the penumbra spans x ∈ [-0.3, 0.7] on the receiver: F is continuous across both ends, 0 inside the umbra's
    side only if the light is hidden whole (it is not here: the occluder's other edges leave part of it), and
    strictly between the umbra's and the unlit values inside."""
    light, mesh = SCENES["one"]
    xs = torch.tensor([-0.3 - 1e-9, -0.3, -0.3 + 1e-9, 0.7 - 1e-9, 0.7, 0.7 + 1e-9], dtype=F64)
    pts = torch.stack([xs, torch.zeros_like(xs), torch.zeros_like(xs)], 1)
    F = light_form_factor(pts, UP.expand_as(pts), light, mesh)
    assert float((F[1] - F[0]).abs()) < 1e-7 and float((F[2] - F[1]).abs()) < 1e-7
    assert float((F[4] - F[3]).abs()) < 1e-7 and float((F[5] - F[4]).abs()) < 1e-7
    unlit = light_form_factor(pts, UP.expand_as(pts), light)
    assert torch.allclose(F[4:], unlit[4:], atol=1e-7)                      # from x = 0.7 on: all lit
    assert bool((F[:3] < unlit[:3] - 1e-3).all())


def test_float32_inputs_get_the_float64_answer():
    light, mesh = SCENES["overlap"]
    pts32, light32 = POINTS.float(), light.float()
    mesh32 = Mesh(mesh.verts.float(), mesh.faces)
    f32 = light_form_factor(pts32, UP.float().expand(5, 3), light32, mesh32)
    f64 = light_form_factor(pts32.double(), UP.expand(5, 3), light32.double(), Mesh(mesh32.verts.double(), mesh.faces))
    assert f32.dtype == torch.float32
    assert torch.allclose(f32.double(), f64, atol=1e-7)


@pytest.mark.parametrize("bad, match", [
    (dict(light=torch.zeros(2, 3)), "K >= 3"),
    (dict(light=torch.tensor([[0.0, 2, 0], [1, 2, 0], [2, 2, 0]])), "no area"),
    (dict(light=torch.tensor([[0.0, 2, 0], [1, 2, 0], [1, 2, 1], [0, 2.5, 1]])), "planar"),
    (dict(light=torch.tensor([[0.0, 2, 0], [1, 2, 0], [0.3, 2, 0.3], [0, 2, 1]])), "convex"),
    (dict(points=torch.full((2, 3), float("nan"))), "points"),
    (dict(normals=torch.zeros(2, 3)), "zero vector"),
    (dict(normals=torch.ones(3, 3)), "shape of points"),
    (dict(occluders=3), "Mesh or None"),
])
def test_bad_input_is_named(bad, match):
    args = dict(points=torch.zeros(2, 3), normals=torch.tensor([[0.0, 1, 0], [0, 1, 0]]),
                light=square_light().float(), occluders=None)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        light_form_factor(**args)


# ------------------------------------------------------------------------------------ the image it lights

def _lit_scene(size=8):
    from course.shadows.gradients import shadow_scene
    mesh, cam, colors, _ = shadow_scene("floater", size)
    light = torch.tensor([[-0.3, 3.0, -0.3], [0.3, 3.0, -0.3], [0.3, 3.0, 0.3], [-0.3, 3.0, 0.3]], dtype=F64)
    return mesh, cam, colors, light                                         # facing down (-y)


def test_the_image_is_what_supersampling_with_the_exact_form_factor_converges_to():
    """Each pixel's quadrature over the exact visible pieces against s × s pixel samples, each the ray-cast face's
    colour times (ambient + intensity F) with F exact at the hit point: the difference falls with s (the
    supersampled image is the estimate, the primary visibility's edges its error)."""
    from course.camera import Camera
    from course.raytrace import raycast
    from course.shadows.area import area_light_image, light_form_factor
    mesh, cam, colors, light = _lit_scene()
    image = area_light_image(mesh, cam, colors, light, ambient=0.1, intensity=5.0)
    errors = []
    for s in (2, 6):
        K = cam.K.clone()
        K[:2] *= s
        big = Camera(K, cam.R, cam.t, cam.width * s, cam.height * s, cam.near, cam.far, cam.orthographic)
        frags = raycast(mesh, big)
        fid = frags.face_id.reshape(-1)
        hit = fid >= 0
        tri = mesh.verts[mesh.faces[fid[hit]]]
        x = (frags.bary.reshape(-1, 3)[hit][:, :, None] * tri).sum(1)
        n = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1)
        eye = -cam.R.T @ cam.t
        n = torch.where((((eye - x) * n).sum(1) < 0)[:, None], -n, n)
        F = torch.stack([light_form_factor(x[i:i + 1], n[i:i + 1], light,
                                           Mesh(mesh.verts, mesh.faces[torch.arange(mesh.faces.shape[0]) != fid[hit][i]]))[0]
                         for i in range(x.shape[0])])
        flat = torch.zeros(fid.shape[0], 3, dtype=F64)
        flat[hit] = colors[fid[hit]] * (0.1 + 5.0 * F)[:, None]
        sampled = flat.view(cam.height, s, cam.width, s, 3).mean((1, 3))
        errors.append(float((sampled - image).abs().mean()))
    assert errors[1] < errors[0] / 2 and errors[1] < 2e-3, errors


def test_the_quadrature_converges_and_its_error_is_small():
    from course.shadows.area import area_light_image
    mesh, cam, colors, light = _lit_scene(6)
    images = [area_light_image(mesh, cam, colors, light, intensity=5.0, subdivide=k) for k in (1, 2, 4)]
    e1, e2 = float((images[0] - images[2]).abs().max()), float((images[1] - images[2]).abs().max())
    assert e2 < e1 / 2 and e1 < 1e-3, (e1, e2)
    lit = images[2] - area_light_image(mesh, cam, colors, light, intensity=0.0)
    assert float(lit.abs().max()) > 1e-2                                    # the light shows


def test_the_images_gradient_is_the_derivative():
    """d Σ w ⊙ image w.r.t. the light's position (a translation), the occluder's vertices and the camera's t, by
    autograd against central differences (steps 1e-5 and 1e-6 agree)."""
    from course.camera import Camera
    from course.shadows.area import area_light_image
    mesh, cam, colors, light = _lit_scene(6)
    w = torch.rand(6, 6, 3, generator=torch.Generator().manual_seed(0), dtype=F64)
    shift = torch.zeros(3, dtype=F64, requires_grad=True)
    occ = mesh.verts[3:].clone().requires_grad_()
    t = cam.t.clone().requires_grad_()

    def loss(shift, occ, t):
        verts = torch.cat([mesh.verts[:3], occ])
        c = Camera(cam.K, cam.R, t, cam.width, cam.height, cam.near, cam.far, cam.orthographic)
        return (area_light_image(Mesh(verts, mesh.faces), c, colors, light + shift, intensity=5.0) * w).sum()
    grads = torch.autograd.grad(loss(shift, occ, t), (shift, occ, t))
    base = [shift.detach(), occ.detach(), t.detach()]
    for k, g in enumerate(grads):
        def f(v, k=k):
            args = list(base)
            args[k] = v
            return loss(*args)
        if k == 1:                                                          # one occluder vertex (time)
            g = g[1]

            def f(v, f=f):                                                  # noqa: F811
                occ = base[1].clone()
                occ[1] = v
                return f(occ)
            fd5, fd6 = _fd(f, base[1][1], 1e-5), _fd(f, base[1][1], 1e-6)
        else:
            fd5, fd6 = _fd(f, base[k], 1e-5), _fd(f, base[k], 1e-6)
        scale = max(float(fd6.abs().max()), 1e-3)
        assert float((fd5 - fd6).abs().max()) < 1e-4 * scale, (k, fd5, fd6)
        assert float((g - fd6).abs().max()) < 1e-4 * scale, (k, g, fd6)


@pytest.mark.parametrize("name", list(SCENES))
def test_a_point_gets_the_same_answer_alone_or_in_a_batch(name):
    """The points are clipped together in padded batches (``area._visible_batch``): a point's form factor and
    gradient do not depend on the others in its batch or the chunk size (a wall touching the receiver plane
    leaves a corner at a point's own level in another point's unused slots: it must not leak a NaN)."""
    from course.shadows import area
    light, mesh = SCENES[name]
    pts = torch.cat([POINTS, POINTS[:3] + torch.tensor([0.21, 0.0, -0.17], dtype=F64)])
    nrm = UP.expand_as(pts) + 0.1 * torch.sin(torch.arange(24, dtype=F64)).view(8, 3)
    leaf = pts.clone().requires_grad_()
    together = light_form_factor(leaf, nrm, light, mesh)
    grad, = torch.autograd.grad(together.sum(), leaf)
    assert bool(torch.isfinite(grad).all())
    for i in range(pts.shape[0]):
        one = pts[i:i + 1].clone().requires_grad_()
        alone = light_form_factor(one, nrm[i:i + 1], light, mesh)
        g1, = torch.autograd.grad(alone.sum(), one)
        assert float((alone[0] - together[i]).abs()) <= 1e-15
        assert float((g1[0] - grad[i]).abs().max()) <= 1e-12
    n64 = nrm / nrm.norm(dim=1, keepdim=True)
    tris = mesh.verts[mesh.faces]
    chunked = area._form_factors(pts, n64, light, tris, None, chunk=3)
    assert float((chunked - together.detach()).abs().max()) <= 1e-15
