"""The checks of lecture 4's graded tasks (shading): 4.1 lambert, 4.2 blinn_phong, 4.3 sample_bilinear.

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


@task("4.1", "lambert", points=2)
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


@task("4.2", "blinn_phong", points=2)
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


@task("4.3", "sample_bilinear", points=3)
def _check_sample_bilinear(impl):
    ref = _ref("course.shading", "sample_texture")
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
