"""The light's direction recovered from one image of its shadows (course.shadows.fit): from 30° and more away
to under 1°, by the exact gradient and by the boundary term (Reynolds)."""
import math

import pytest
import torch

from course.shadows.fit import LightFitSettings, angle_between, fit_light_direction
from course.shadows.gradients import shadow_scene, shadowed_coverage


def _rotated(v, axis, degrees):
    """v (3,) rotated about axis (3,) by the angle (Rodrigues)."""
    k = axis / axis.norm()
    a = math.radians(degrees)
    return v * math.cos(a) + torch.linalg.cross(k, v, dim=0) * math.sin(a) + k * (k @ v) * (1 - math.cos(a))


@pytest.mark.parametrize("method,axis,degrees", [("exact", (0.0, 0.0, 1.0), 30.0),
                                                 ("reynolds", (1.0, 0.0, 0.3), 35.0)])
def test_light_direction_from_its_shadow(method, axis, degrees):
    mesh, cam, colors, truth = shadow_scene("floater", 24)
    target = shadowed_coverage(mesh, cam, colors, truth)
    unit = truth / truth.norm()
    init = _rotated(unit, torch.linalg.cross(unit, torch.tensor(axis, dtype=torch.float64), dim=0), degrees)
    assert angle_between(init, truth) >= 30 - 1e-9
    fit = fit_light_direction(mesh, cam, colors, target, init, truth=truth,
                              settings=LightFitSettings(method=method))
    assert fit.angles[-1] <= 1.0
    assert fit.losses[-1] < fit.losses[0] / 100


def test_bad_settings():
    mesh, cam, colors, truth = shadow_scene("floater", 8)
    target = shadowed_coverage(mesh, cam, colors, truth)
    with pytest.raises(ValueError, match="method"):
        fit_light_direction(mesh, cam, colors, target, truth, settings=LightFitSettings(method="soft"))
    with pytest.raises(ValueError, match="target"):
        fit_light_direction(mesh, cam, colors, target[:4], truth)
