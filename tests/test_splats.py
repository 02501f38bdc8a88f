"""Gaussian splatting (course.splats.render_gaussians) against an independent implementation of Kerbl et al.'s
rules written here in plain Python floats, one pixel and one Gaussian at a time; the image independent of the
tile size; autograd against float64 central differences on scenes away from the decisions (depth swaps and
cut-offs), and not across them; bad input named."""
import math

import pytest
import torch

from course.camera import Camera
from course.splats import project_gaussians, render_gaussians

F64 = torch.float64


# ------------------------------------------------------------------ the rules, one pixel at a time, in floats

def _rotation(q):
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def _matmul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(len(B))) for j in range(len(B[0]))] for i in range(len(A))]


def _transpose(A):
    return [list(r) for r in zip(*A)]


def reference_render(means, scales, rotations, opacities, colors, camera, background):
    """Kerbl et al.'s forward pass, literally: cull z <= 0.2, Σ = R S Sᵀ Rᵀ, Σ₂ = J W Σ Wᵀ Jᵀ + 0.3 I, sort by
    view depth, per pixel centre: α = min(0.99, o exp(-½ dᵀ Σ₂⁻¹ d)), skip α < 1/255, stop before T < 1e-4."""
    K, R, t = camera.K.tolist(), camera.R.tolist(), camera.t.tolist()
    splats = []
    for m, s, q, o, c in zip(means.tolist(), scales.tolist(), rotations.tolist(), opacities.tolist(), colors.tolist()):
        cam = [sum(R[i][k] * m[k] for k in range(3)) + t[i] for i in range(3)]
        if cam[2] <= 0.2:
            continue
        Rq = _rotation(q)
        M = [[Rq[i][j] * s[j] for j in range(3)] for i in range(3)]
        cov = _matmul(M, _transpose(M))
        x, y, z = cam
        if camera.orthographic:
            P = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
            u, v = x, y
        else:
            P = [[1 / z, 0.0, -x / (z * z)], [0.0, 1 / z, -y / (z * z)]]
            u, v = x / z, y / z
        K2 = [[K[0][0], K[0][1]], [K[1][0], K[1][1]]]
        J = _matmul(K2, P)
        T = _matmul(J, R)
        cov2 = _matmul(_matmul(T, cov), _transpose(T))
        a, b, d = cov2[0][0] + 0.3, cov2[0][1], cov2[1][1] + 0.3
        det = a * d - b * b
        px = K[0][0] * u + K[0][1] * v + K[0][2]
        py = K[1][0] * u + K[1][1] * v + K[1][2]
        splats.append((z, (px, py), (d / det, -b / det, a / det), o, c))
    splats.sort(key=lambda g: g[0])
    image = []
    for i in range(camera.height):
        row = []
        for j in range(camera.width):
            C, T = [0.0, 0.0, 0.0], 1.0
            for _, (mx, my), (A, B, Cc), o, col in splats:
                dx, dy = j + 0.5 - mx, i + 0.5 - my
                power = -0.5 * (A * dx * dx + 2 * B * dx * dy + Cc * dy * dy)
                alpha = min(0.99, o * math.exp(power))
                if alpha < 1.0 / 255.0:
                    continue
                test = T * (1 - alpha)
                if test < 1e-4:
                    break
                C = [C[k] + col[k] * alpha * T for k in range(3)]
                T = test
            row.append([C[k] + T * background[k] for k in range(3)])
        image.append(row)
    return torch.tensor(image, dtype=F64)


def random_scene(seed, n=12, spread=1.0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g, dtype=F64) - 0.5) * 2 * spread
    scales = 0.05 + 0.25 * torch.rand(n, 3, generator=g, dtype=F64)
    q = torch.randn(n, 4, generator=g, dtype=F64)
    rotations = q / q.norm(dim=1, keepdim=True)
    opacities = 0.3 + 0.65 * torch.rand(n, generator=g, dtype=F64)
    colors = torch.rand(n, 3, generator=g, dtype=F64)
    return means, scales, rotations, opacities, colors


def camera(orthographic=False, width=20, height=16):
    if orthographic:
        return Camera.look_at((0.4, 0.6, 4.0), (0.0, 0.0, 0.0), ortho_height=3.0, width=width, height=height,
                              dtype=F64)
    return Camera.look_at((0.4, 0.6, 4.0), (0.0, 0.0, 0.0), fov_y=45.0, width=width, height=height, dtype=F64)


BACKGROUND = (0.1, 0.2, 0.3)


@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_image_follows_the_reference_rules(seed, orthographic):
    scene = random_scene(seed)
    cam = camera(orthographic)
    got = render_gaussians(*scene, cam, BACKGROUND)
    want = reference_render(*scene, cam, BACKGROUND)
    assert got.shape == (16, 20, 3)
    assert float((got - want).abs().max()) < 1e-13


def test_culling_cut_offs_and_early_stop_are_the_references():
    """A Gaussian behind the near distance, one so faint it never reaches 1/255, and a stack of opaque ones that
    takes the transmittance below 1e-4 (the rest not added)."""
    cam = camera()
    eye = torch.tensor([0.4, 0.6, 4.0], dtype=F64)
    toward = -eye / eye.norm()
    means = torch.stack([eye + 0.1 * toward] + [toward * 0.01 * k for k in range(6)] + [torch.zeros(3, dtype=F64)])
    n = means.shape[0]
    scales = torch.full((n, 3), 0.4, dtype=F64)
    rotations = torch.tensor([[1.0, 0, 0, 0]], dtype=F64).expand(n, 4)
    opacities = torch.tensor([0.9] + [0.99] * 6 + [0.003], dtype=F64)       # last: o < 1/255, never drawn
    colors = torch.rand(n, 3, generator=torch.Generator().manual_seed(5), dtype=F64)
    got = render_gaussians(means, scales, rotations, opacities, colors, cam, BACKGROUND)
    want = reference_render(means, scales, rotations, opacities, colors, cam, BACKGROUND)
    assert float((got - want).abs().max()) < 1e-13
    without_faint = render_gaussians(means[:-1], scales[:-1], rotations[:-1], opacities[:-1], colors[:-1], cam,
                                     BACKGROUND)
    assert torch.equal(got, without_faint)


@pytest.mark.parametrize("tile", [1, 3, 7, 64])
def test_the_image_does_not_depend_on_the_tiles(tile):
    scene = random_scene(3, n=30)
    cam = camera(width=23, height=17)
    assert float((render_gaussians(*scene, cam, BACKGROUND, tile=tile)
                  - render_gaussians(*scene, cam, BACKGROUND, tile=16)).abs().max()) < 1e-15


def _margins(scene, cam):
    """The smallest relative gaps to the decisions: between two view depths, and |α - 1/255| at any pixel."""
    means, scales, rotations, opacities, colors = scene
    mean2, cov2, z = project_gaussians(means, scales, rotations, cam)
    zs = z.sort().values
    depth_gap = float((zs[1:] - zs[:-1]).min())
    ii, jj = torch.meshgrid(torch.arange(cam.height, dtype=F64) + 0.5, torch.arange(cam.width, dtype=F64) + 0.5,
                            indexing="ij")
    p = torch.stack([jj.reshape(-1), ii.reshape(-1)], -1)
    d = p[:, None, :] - mean2[None]
    inv = torch.linalg.inv(cov2)
    q = torch.einsum("pni,nij,pnj->pn", d, inv, d)
    alpha = opacities * torch.exp(-0.5 * q)
    return depth_gap, float((alpha - 1 / 255).abs().min()), float((alpha - 0.99).abs().min())


@pytest.mark.parametrize("seed", [1, 6])
def test_autograd_is_the_derivative_away_from_the_decisions(seed):
    """Every parameter and the camera's translation: autograd against central differences (steps 1e-6 and 1e-7
    agree: converged), on random scenes whose depths differ and whose alphas stay clear of 1/255 and 0.99 by
    more than a step can move them."""
    scene = random_scene(seed, n=8)
    cam = camera(width=12, height=10)
    depth_gap, cut_gap, clamp_gap = _margins(scene, cam)
    assert depth_gap > 1e-3 and cut_gap > 1e-5 and clamp_gap > 1e-5, (depth_gap, cut_gap, clamp_gap)
    weights = torch.rand(10, 12, 3, generator=torch.Generator().manual_seed(9), dtype=F64)
    leaves = [v.clone().requires_grad_() for v in scene]
    t = cam.t.clone().requires_grad_()

    def loss(values, translation):
        c = Camera(cam.K, cam.R, translation, cam.width, cam.height, cam.near, cam.far)
        return (render_gaussians(*values, c, BACKGROUND) * weights).sum()
    grads = torch.autograd.grad(loss(leaves, t), leaves + [t])
    base = list(scene) + [cam.t]
    for k, g in enumerate(grads):
        def f(v, k=k):
            values = list(base)
            values[k] = v
            return float(loss(values[:5], values[5]))
        fd = {}
        for h in (1e-6, 1e-7):
            fd[h] = torch.zeros_like(base[k])
            flat = fd[h].view(-1)
            for i in range(flat.numel()):
                e = torch.zeros(flat.numel(), dtype=F64)
                e[i] = h
                e = e.view_as(base[k])
                flat[i] = (f(base[k] + e) - f(base[k] - e)) / (2 * h)
        scale = max(1.0, float(fd[1e-6].abs().max()))
        assert float((fd[1e-6] - fd[1e-7]).abs().max()) < 1e-6 * scale, k
        assert float((g - fd[1e-6]).abs().max()) < 1e-6 * scale, (k, g, fd[1e-6])


def test_autograd_misses_the_jump_when_two_gaussians_swap_depth():
    """Two overlapping Gaussians whose depths cross as one moves along the view direction: the image jumps at
    the swap; central differences straddling it see the jump (divided by 2h), autograd does not."""
    cam = camera(width=8, height=8)
    eye = torch.tensor([0.4, 0.6, 4.0], dtype=F64)
    toward = -eye / eye.norm()
    means = torch.stack([torch.zeros(3, dtype=F64), 0.05 * torch.tensor([1.0, 0.0, 0.0], dtype=F64)])
    scales = torch.full((2, 3), 0.5, dtype=F64)
    rotations = torch.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]], dtype=F64)
    opacities = torch.tensor([0.8, 0.8], dtype=F64)
    colors = torch.tensor([[1.0, 0, 0], [0, 0, 1.0]], dtype=F64)

    def image(s):
        m = means.clone()
        m[1] = m[1] + s * toward                                            # depth of the second: its own + s
        return render_gaussians(m, scales, rotations, opacities, colors, cam, BACKGROUND)
    swap = float(((means[0] - means[1]) @ toward))                          # s where the depths are equal
    jump = (image(swap + 1e-9) - image(swap - 1e-9)).abs().max()
    assert float(jump) > 0.05                                               # the image jumps at the swap
    s = torch.tensor(swap + 1e-7, dtype=F64, requires_grad=True)
    m = means.clone()
    m[1] = m[1] + s * toward
    red = lambda im: im[..., 0].sum()                                      # (the RGB sum is the same in either
    g, = torch.autograd.grad(red(render_gaussians(m, scales, rotations, opacities, colors, cam, BACKGROUND)), s)
    h = 1e-4                                                                # order: α c + (1 - α) α c')
    fd = float((red(image(swap + 1e-7 + h)) - red(image(swap + 1e-7 - h))) / (2 * h))
    full_jump = float(red(image(swap + 1e-9)) - red(image(swap - 1e-9)))
    assert abs(full_jump) > 0.1
    assert abs(fd - float(g) - full_jump / (2 * h)) < 0.05 * abs(full_jump / (2 * h))


@pytest.mark.parametrize("bad, match", [
    (dict(means=torch.zeros(2, 2)), "means must have shape"),
    (dict(scales=torch.zeros(2, 3)), "scales must be positive"),
    (dict(rotations=torch.ones(2, 4)), "unit quaternions"),
    (dict(opacities=torch.tensor([0.5, 1.5])), r"opacities must lie in \[0, 1\]"),
    (dict(colors=torch.zeros(2, 4)), "colors must have shape"),
    (dict(means=torch.tensor([[0.0, 0, float("nan")], [0, 0, 0]])), "means"),
])
def test_bad_input_is_named(bad, match):
    args = dict(means=torch.zeros(2, 3), scales=torch.full((2, 3), 0.1), rotations=torch.tensor([[1.0, 0, 0, 0]] * 2),
                opacities=torch.tensor([0.5, 0.5]), colors=torch.zeros(2, 3))
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        render_gaussians(camera=camera(), **args)


def test_one_gaussian_as_a_volume_has_the_splats_opacity_along_its_central_ray():
    """``render_gaussians_volume`` sets each Gaussian's density so that the ray from the camera through its mean
    sees opacity o: the pixel whose centre ray passes through the mean (odd image size, the camera looking at
    it) is o c + (1 - o) background, to the quadrature's error (the midpoint rule on a smooth profile: 1e-11 from
    64 samples on)."""
    from course.splats import render_gaussians_volume
    cam = Camera.look_at((0.3, 0.2, 4.0), (0.0, 0.0, 0.0), fov_y=30.0, width=31, height=31, dtype=F64)
    means = torch.zeros(1, 3, dtype=F64)
    scales = torch.tensor([[0.3, 0.2, 0.25]], dtype=F64)
    q = torch.tensor([[0.9, 0.1, -0.3, 0.2]], dtype=F64)
    rotations = q / q.norm()
    o, c = torch.tensor([0.6], dtype=F64), torch.tensor([[1.0, 0.5, 0.2]], dtype=F64)
    want = o * c[0] + (1 - o) * torch.tensor(BACKGROUND, dtype=F64)
    errors = [float((render_gaussians_volume(means, scales, rotations, o, c, cam, BACKGROUND, samples=n)[15, 15]
                     - want).abs().max()) for n in (64, 512)]
    assert max(errors) < 1e-9, errors
    leaf = means.clone().requires_grad_()
    g, = torch.autograd.grad(render_gaussians_volume(leaf, scales, rotations, o, c, cam, BACKGROUND, samples=64).sum(),
                             leaf)
    assert bool(torch.isfinite(g).all()) and float(g.abs().sum()) > 0


def test_autograd_misses_the_jump_at_the_one_in_255_cut_off():
    """One Gaussian over the background: as its opacity o grows, its α at an outer pixel crosses 1/255 and the
    pixel jumps by α (c - background) there (the Gaussian appears); autograd sees only the smooth part on each
    side, and central differences straddling the cut see the jump divided by 2h."""
    cam = camera(width=9, height=9)
    means = torch.zeros(1, 3, dtype=F64)
    scales = torch.full((1, 3), 0.15, dtype=F64)
    rotations = torch.tensor([[1.0, 0, 0, 0]], dtype=F64)
    colors = torch.tensor([[1.0, 1.0, 1.0]], dtype=F64)
    mean2, cov2, _ = project_gaussians(means, scales, rotations, cam)
    ii, jj = torch.meshgrid(torch.arange(9, dtype=F64) + 0.5, torch.arange(9, dtype=F64) + 0.5, indexing="ij")
    d = torch.stack([jj, ii], -1) - mean2[0]                                # every pixel centre
    fall = torch.exp(-0.5 * torch.einsum("hwi,ij,hwj->hw", d, torch.linalg.inv(cov2[0]), d))
    row, col = divmod(int((fall - 0.02).abs().argmin()), 9)                 # a pixel where it falls to about 2 %
    falloff = float(fall[row, col])
    o_cut = (1 / 255) / falloff                                             # o where α at that pixel is 1/255
    assert 0.05 < o_cut < 0.95

    def pixel(o):
        return render_gaussians(means, scales, rotations, torch.tensor([o], dtype=F64), colors, cam,
                                BACKGROUND)[row, col, 0]
    jump = float(pixel(o_cut * (1 + 1e-9)) - pixel(o_cut * (1 - 1e-9)))
    assert abs(jump - (1 / 255) * (1.0 - BACKGROUND[0])) < 1e-8               # α (c - background) at the cut
    o = torch.tensor([o_cut * (1 + 1e-6)], dtype=F64, requires_grad=True)
    g, = torch.autograd.grad(render_gaussians(means, scales, rotations, o, colors, cam, BACKGROUND)[row, col, 0], o)
    assert abs(float(g) - falloff * (1.0 - BACKGROUND[0])) < 1e-9           # the smooth part: dα/do (c - bg)
    h = 1e-4
    fd = float(pixel(o_cut + h) - pixel(o_cut - h)) / (2 * h)
    assert abs(fd - float(g) - jump / (2 * h)) < 1e-3 * abs(jump / (2 * h))


def test_the_boundary_term_closes_the_gap_at_a_swap():
    """Averaged over a window around the swap, autograd's derivative is far from the derivative of the averaged
    loss; adding the jump times the window's density (the boundary term) closes the gap (to the cut-off jumps the
    window also holds: 1e-4 of it)."""
    from course.splats import swap_study
    study = swap_study(width=0.05, samples=16, size=12)
    assert study["jump"] > 1.0
    assert abs(study["autograd"] - study["smoothed"]) > 0.9 * abs(study["smoothed"])
    assert abs(study["corrected"] - study["smoothed"]) < 1e-4 * abs(study["smoothed"])


def test_splat_and_volume_differ_most_where_gaussians_interpenetrate():
    from course.splats import splat_volume_study
    study = splat_volume_study(size=16, samples=128)
    assert set(study) == {"alone", "interpenetrating", "off_axis"}
    assert 0 < study["alone"] < 0.1 and study["interpenetrating"] > 2 * study["alone"]


def _one_gaussian(seed):
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(1, 4, generator=g, dtype=F64)
    return (torch.rand(1, 3, generator=g, dtype=F64) * 0.4 - 0.2, 0.15 + 0.2 * torch.rand(1, 3, generator=g, dtype=F64),
            q / q.norm(), torch.tensor([0.7], dtype=F64), torch.rand(1, 3, generator=g, dtype=F64))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_splat_steps_start_at_the_reference_and_end_at_the_medium(seed):
    """The first step is render_gaussians; with no cut-off in play (every α in [1/255, 0.99], T above 1e-4) the
    second equals it; for one Gaussian the exact footprint is the medium (to the quadrature's error)."""
    from course.splats import render_gaussians_volume, splat_step
    scene = _one_gaussian(seed)
    cam = Camera.look_at((0.3, 0.2, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=12, height=10, dtype=F64)
    assert torch.equal(splat_step(*scene, cam, BACKGROUND, step="reference"),
                       render_gaussians(*scene, cam, BACKGROUND))
    wide = (scene[0], scene[1] * 4) + scene[2:]                             # α above 1/255 on every pixel
    assert float((splat_step(*wide, cam, BACKGROUND, step="no cut-offs")
                  - render_gaussians(*wide, cam, BACKGROUND)).abs().max()) < 1e-14
    exact = splat_step(*scene, cam, BACKGROUND, step="exact footprint")
    medium = render_gaussians_volume(*scene, cam, BACKGROUND, samples=256)
    assert float((exact - medium).abs().max()) < 1e-9


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_orthographic_footprint_is_exactly_the_linearised_one(seed):
    """In an orthographic view the projection is linear: the splat's footprint (without the 0.3 px² blur) is the
    3D Gaussian integrated along the rays, exactly; in perspective it is not."""
    from course.splats import splat_step
    scene = _one_gaussian(seed)
    ortho = camera(orthographic=True)
    a = splat_step(*scene, ortho, BACKGROUND, step="exponential falloff")
    b = splat_step(*scene, ortho, BACKGROUND, step="exact footprint")
    assert float((a - b).abs().max()) < 1e-12
    from course.splats import render_gaussians_volume
    medium = render_gaussians_volume(*scene, ortho, BACKGROUND, samples=256)   # the medium along parallel rays
    assert float((medium - b).abs().max()) < 1e-9
    persp = Camera.look_at((0.0, 0.0, 1.5), (0.0, 0.0, 0.0), fov_y=90.0, width=20, height=16, dtype=F64)
    a = splat_step(*scene, persp, BACKGROUND, step="exponential falloff")
    b = splat_step(*scene, persp, BACKGROUND, step="exact footprint")
    assert float((a - b).abs().max()) > 1e-3


def test_the_causes_split_the_splat_against_the_medium():
    """Each scene's difference split by cause: the five causes' images telescope to the total; a Gaussian alone
    differs by its falloff, interpenetrating ones by the sort, the one in the corner of the wide view by the blur
    and the linearisation (the lecture prints these)."""
    from course.splats import CAUSES, splat_step, splat_volume_causes
    study = splat_volume_causes(size=16, samples=64)
    for row in study.values():
        assert row["total"] <= sum(row[c] for c in CAUSES) + 1e-12
        assert row["quadrature"] < 1e-5
        assert abs(row["cut-offs"] - 1 / 255) < 1e-3                         # one pixel's α crossing the cut
    alone, pair, corner = study["alone"], study["interpenetrating"], study["off_axis"]
    assert alone["sort"] < 1e-8 and corner["sort"] < 1e-8                  # one Gaussian: nothing to sort
    assert max(alone, key=lambda c: alone[c] if c in CAUSES else 0) == "falloff"
    assert pair["sort"] > 2 * pair["falloff"]
    assert corner["linearisation"] > 5 * alone["linearisation"]
    with pytest.raises(ValueError, match="step must be one of"):
        splat_step(*_one_gaussian(0), camera(), step="no sort")


def test_float32_scenes_render_in_float32_close_to_float64():
    scene = random_scene(7, n=20)
    cam = camera()
    f64 = render_gaussians(*scene, cam, BACKGROUND)
    f32 = render_gaussians(*(v.float() for v in scene), cam, BACKGROUND)
    assert f32.dtype == torch.float32
    assert float((f32.double() - f64).abs().max()) < 1e-4


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_the_same_image_and_gradient_on_cuda():
    """render_gaussians on a CUDA device (means and camera there): the CPU's image and gradient to rounding;
    the medium and the splat steps likewise."""
    from course.splats import render_gaussians_volume, splat_step
    scene = random_scene(3, n=30)
    cam = camera()
    leaves = [v.clone().requires_grad_() for v in scene]
    cpu = render_gaussians(*leaves, cam, BACKGROUND)
    cpu_grad = torch.autograd.grad((cpu ** 2).sum(), leaves)
    dev = [v.cuda().requires_grad_() for v in scene]
    gpu = render_gaussians(*dev, cam.to(device="cuda"), BACKGROUND)
    assert gpu.device.type == "cuda"
    gpu_grad = torch.autograd.grad((gpu ** 2).sum(), dev)
    assert float((gpu.cpu() - cpu).abs().max()) < 1e-12
    for a, b in zip(cpu_grad, gpu_grad):
        assert float((b.cpu() - a).abs().max()) < 1e-10 * (1 + float(a.abs().max()))
    small = Camera.look_at((0.4, 0.6, 4.0), (0.0, 0.0, 0.0), fov_y=45.0, width=8, height=6, dtype=F64)
    a = render_gaussians_volume(*scene, small, BACKGROUND, samples=32)
    b = render_gaussians_volume(*(v.cuda() for v in scene), small.to(device="cuda"), BACKGROUND, samples=32)
    assert float((b.cpu() - a).abs().max()) < 1e-12
    a = splat_step(*scene, small, BACKGROUND)
    b = splat_step(*(v.cuda() for v in scene), small.to(device="cuda"), BACKGROUND)
    assert float((b.cpu() - a).abs().max()) < 1e-12
