"""The checks of lecture 4's graded tasks (shading): 4.1 lambert, 4.2 blinn_phong, 4.3 sample_bilinear,
4.4 mip_level.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

import torch

from .helpers import _call, _diagnose, _num, _ref, generator, grade_parts, require
from .registry import task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


def _unit(n: int, seed: int, dtype=torch.float32) -> torch.Tensor:
    v = torch.randn(n, 3, generator=generator(seed), dtype=torch.float64)
    return (v / v.norm(dim=1, keepdim=True)).to(dtype)


@task("4.1", "lambert", points=2, reference=("course.shading", "lambert"))
def _check_lambert(impl):
    ref = _ref("course.shading", "lambert")

    def run(normal, light, albedo, name, check_dtype):
        cos = (normal.to(torch.float64) * light.to(torch.float64)).sum(-1, keepdim=True)
        a = albedo.to(torch.float64)
        require(_diagnose(_call(impl, normal, light, albedo), ref(normal, light, albedo), name, [
            (a * cos, "negative where the light is behind the surface: clamp, max(0, n·l)"),
            (a * cos.abs(), "a light behind the surface gives 0, not |n·l|: clamp, max(0, n·l)"),
            (a * (-cos).clamp_min(0), "light_dir points toward the light: use n·l, not -n·l")],
            check_dtype=check_dtype))

    def stress():
        normal = torch.cat([_unit(10, 42, torch.float64), torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
                                                                       dtype=torch.float64)])
        light = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)                  # n·l = 1 and exactly 0
        run(normal, light, torch.tensor([0.9, 0.5, 0.2], dtype=torch.float64),
            "lambert with light_dir (3,) and albedo (3,), float64", True)
    return grade_parts((1, "per-point light and albedo", lambda: run(
                            _unit(12, 41), _unit(12, 43), torch.rand(12, 3, generator=generator(44)),
                            "lambert(12 normals)", False)),
                       (1, "broadcasting, grazing light, float64", stress))


@task("4.2", "blinn_phong", points=2, reference=("course.shading", "blinn_phong"))
def _check_blinn_phong(impl):
    ref = _ref("course.shading", "blinn_phong")

    def run(n, l, v, shininess, name, check_dtype):
        n64, l64, v64 = (x.to(torch.float64) for x in (n, l, v))
        h = l64 + v64
        unit_h = h / h.norm(dim=-1, keepdim=True)
        lit = (n64 * l64).sum(-1) > 0
        cos, cos_raw = (n64 * unit_h).sum(-1), (n64 * h).sum(-1)
        phong = _ref("course.shading", "phong")(n64, l64, v64, shininess)
        require(_diagnose(_call(impl, n, l, v, shininess), ref(n, l, v, shininess), name, [
            (cos.clamp_min(0) ** shininess, "a light behind the surface (n·l <= 0) makes no highlight: "
             "return 0 there"),
            (torch.where(lit, cos_raw.clamp_min(0) ** shininess, 0.0), "normalise the half vector: "
             "h = (l + v) / |l + v|"),
            (torch.where(lit, cos ** shininess, 0.0), "clamp n·h at 0 before raising it to the shininess"),
            (phong, "that is Phong's r·v; Blinn-Phong uses the half vector h = normalize(l + v)")],
            check_dtype=check_dtype))

    def basic():
        behind = torch.tensor([[0.0, 0.0, 1.0], [0.995, 0.0, -0.0998], [-0.6, 0.0, 0.8]])  # n; l just behind; v
        n, l, v = (torch.cat([_unit(12, seed), behind[k:k + 1]]) for k, seed in enumerate((48, 49, 50)))
        run(n, l, v, 8.0, "blinn_phong(13 points, shininess=8)", False)

    def stress():
        head_on = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)            # n = l = v: the peak, 1
        n, l, v = (torch.cat([_unit(10, seed, torch.float64), head_on]) for seed in (45, 46, 47))
        for shininess in (1.0, 150.0):
            run(n, l, v, shininess, f"blinn_phong(shininess={_num(shininess)}), float64", True)
    return grade_parts((1, "highlights", basic), (1, "shininess 1 and 150, float64", stress))


def _texture_variants(sample, texture, uv) -> list:
    """Lookups with the usual mistakes, each written as the correct lookup at other uv."""
    Ht, Wt = texture.shape[:2]
    u, v = uv[:, 0], uv[:, 1]
    at = lambda uu, vv: sample(texture, torch.stack([uu, vv], -1)).to(torch.float64)   # noqa: E731
    return [(at(u, 1 - v), "v is flipped: v = 0 is the bottom of the image (its last row), v = 1 the top"),
            (at(u + 0.5 / Wt, v - 0.5 / Ht), "missing half-texel offset: texel (r, c) has its centre at "
             "u = (c + 0.5) / Wt, so the column coordinate is u·Wt - 0.5"),
            (at(u + 0.5 / Wt, 1 - v - 0.5 / Ht), "v is flipped (v = 0 is the bottom row) and the half-texel "
             "offset is missing (the column coordinate is u·Wt - 0.5)"),
            (at(v, u), "u and v are swapped: u picks the column, v the row"),
            (sample(texture, uv, mode="nearest").to(torch.float64), "that is a nearest lookup: blend the four "
             "nearest texels by the fractional position"),
            (at((u * (Wt - 1) + 0.5) / Wt, 1 - ((1 - v) * (Ht - 1) + 0.5) / Ht), "texel centres sit at "
             "u = (c + 0.5) / Wt, not c / (Wt - 1)")]


@task("4.3", "sample_bilinear", points=3, reference=("course.textures", "sample_texture"))
def _check_sample_bilinear(impl):
    ref = _ref("course.textures", "sample_texture")
    sample = lambda tex, uv, mode="bilinear": ref(tex, uv, mode=mode)  # noqa: E731

    def run(texture, uv, name, check_dtype=False):
        variants = _texture_variants(sample, texture, uv)
        require(_diagnose(_call(impl, texture, uv), sample(texture, uv), name, variants, check_dtype=check_dtype))

    texture = torch.rand(4, 5, 3, generator=generator(51))                       # (Ht, Wt, C), not square

    def centres():
        rows, cols = torch.meshgrid(torch.arange(4.0), torch.arange(5.0), indexing="ij")
        uv = torch.stack([(cols + 0.5) / 5, 1 - (rows + 0.5) / 4], -1).reshape(-1, 2)
        run(texture, uv, "sample_bilinear at texel centres (must return the texels exactly)")
        run(texture, torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
            "sample_bilinear at the corners uv (0, 0), (1, 0), (0, 1), (1, 1) (the corner texels: (0, 0) is "
            "bottom-left)")

    def stress():
        g = generator(52)
        uv = torch.rand(30, 2, generator=g, dtype=torch.float64) * 2 - 0.5         # beyond [0, 1]: clamp
        run(texture.to(torch.float64), uv, "sample_bilinear with uv outside [0, 1] (clamp to the edge), float64",
            check_dtype=True)
        gray = torch.rand(3, 6, 1, generator=g)
        run(gray, torch.rand(10, 2, generator=g), "sample_bilinear of a one-channel (Ht, Wt, 1) texture")
    return grade_parts((1, "inside the texture", lambda: run(
                            texture, 0.12 + 0.76 * torch.rand(20, 2, generator=generator(53)),
                            "sample_bilinear(20 uv)")),
                       (1, "texel centres and corners", centres), (1, "clamping, one channel, float64", stress))


# ------------------------------------------------------------------------------------- 4.4 mip level

def _mip_variants(dx, dy, size) -> list:
    """Levels computed with the usual mistakes (float64), each with what to fix."""
    Ht, Wt = size
    dx, dy = dx.to(torch.float64), dy.to(torch.float64)
    scaled = lambda d, w, h: d * torch.tensor([w, h], dtype=torch.float64)    # noqa: E731
    length = lambda d, w, h: scaled(d, w, h).norm(dim=-1)                     # noqa: E731
    rho = torch.maximum(length(dx, Wt, Ht), length(dy, Wt, Ht))
    lod = lambda r: torch.log2(r).clamp_min(0)                                # noqa: E731
    return [(torch.log2(torch.maximum(length(dx, 1, 1), length(dy, 1, 1))).clamp_min(0),
             "multiply the derivatives by the texture size (∂u by Wt, ∂v by Ht): ρ is the footprint in texels, "
             "not in uv units"),
            (torch.log2(torch.maximum(length(dx, 1, 1), length(dy, 1, 1))),
             "multiply the derivatives by the texture size (∂u by Wt, ∂v by Ht): ρ is the footprint in texels, "
             "not in uv units"),
            (lod(torch.maximum(length(dx, Ht, Wt), length(dy, Ht, Wt))),
             "Wt and Ht are swapped: u runs along the width (scale ∂u by Wt), v along the height (∂v by Ht)"),
            (lod(torch.minimum(length(dx, Wt, Ht), length(dy, Wt, Ht))),
             "use the longer side of the pixel's footprint, ρ = max(|∂uv/∂x|, |∂uv/∂y|) in texels, not the "
             "shorter one (that level is too sharp and aliases)"),
            (torch.log2(rho), "clamp λ at 0: where a pixel covers less than a texel (ρ < 1) the full-size "
             "texture, level 0, is used"),
            (torch.log(rho).clamp_min(0), "λ = log2 ρ (each level halves the texture), not the natural log"),
            (lod(torch.maximum(scaled(dx, Wt, Ht).abs().amax(-1), scaled(dy, Wt, Ht).abs().amax(-1))),
             "ρ uses the length of each derivative vector, |(Wt ∂u/∂x, Ht ∂v/∂x)|, not its largest component"),
            (lod(rho).floor(), "return λ unrounded: trilinear filtering blends the two levels around it"),
            (lod(rho).round(), "return λ unrounded: trilinear filtering blends the two levels around it")]


def _mip_problem(got, dx, dy, size, name, check_dtype) -> str | None:
    expected = _ref("course.textures", "mip_level")(dx, dy, size)
    message = _diagnose(got, expected, name, _mip_variants(dx, dy, size), check_dtype=check_dtype)
    if message and "inf at" in message:
        message += ": where the derivatives are zero log2 ρ is -inf; clamp λ at 0"
    return message


def _mip_derivatives(n, seed, dtype, low=-1.0, high=8.0):
    """Seeded derivatives whose footprints span 2^low .. 2^high texels of a 64 × 128 texture, in every
    direction, with x and y footprints of different lengths (anisotropic)."""
    g = generator(seed)
    size = 2 ** (low + (high - low) * torch.rand(n, 2, generator=g, dtype=torch.float64))   # (N, 2) texels
    angle = torch.rand(n, 2, generator=g, dtype=torch.float64) * 6.283185307179586
    direction = torch.stack([angle.cos(), angle.sin()], -1)                                  # (N, 2, 2)
    d = size[..., None] * direction / torch.tensor([128.0, 64.0], dtype=torch.float64)       # back to uv
    return d[:, 0].to(dtype), d[:, 1].to(dtype)


@task("4.4", "mip_level", points=3, reference=("course.textures", "mip_level"))
def _check_mip_level(impl):
    def run(dx, dy, size, name, check_dtype=False):
        require(_mip_problem(_call(impl, dx, dy, size), dx, dy, size, name, check_dtype))

    def minified():
        dx, dy = _mip_derivatives(16, 54, torch.float32, low=1.5, high=8.0)
        run(dx, dy, (64, 128), "mip_level(16 pixels, texture_size=(64, 128)), every footprint above 2 texels")

    def magnified():
        dx, dy = _mip_derivatives(16, 55, torch.float32, low=-4.0, high=2.0)
        run(dx, dy, (64, 128), "mip_level(16 pixels, texture_size=(64, 128)), footprints from 1/16 to 4 texels")

    def stress():
        dx, dy = _mip_derivatives(10, 56, torch.float64, low=-20.0, high=20.0)
        zero = torch.zeros(1, 2, dtype=torch.float64)
        one = torch.tensor([[0.25, 0.0]], dtype=torch.float64)                # exactly one texel of a 4-wide map
        run(torch.cat([dx, zero, one, -one]), torch.cat([dy, zero, zero, one.flip(-1)]), (4, 4),
            "mip_level with zero, tiny and huge derivatives, texture_size=(4, 4), float64", True)
        dx, dy = _mip_derivatives(6, 57, torch.float64, low=0.0, high=12.0)
        run(dx, dy, (1, 1024), "mip_level for a 1 × 1024 texture (float64)", True)
    return grade_parts((1, "minification", minified), (1, "magnification and anisotropy", magnified),
                       (1, "zero, tiny and huge derivatives, non-square textures, float64", stress))
