"""Shadows: shadow maps, the exact shadowed image and its gradients, and what is fitted with them.

Lectures 06 (shadow maps), 12 (differentiable shadows) and 14 (soft shadows) use this folder; ``render`` draws its shadows with
``maps``. What each module is:

* ``maps``: shadow maps (lecture 06): the light as a camera (orthographic, perspective, cube map), the two
  passes, the constant and slope-scaled bias, percentage-closer filtering, area lights as many maps.
* ``gradients``: hard shadows in closed form (every face split into lit and shadowed pieces by the occluders'
  projections along the light) and their gradients: exact, finite differences, Reynolds, edge sampling
  (lecture 12).
* ``prefiltered``: variance shadow maps drawn by a smooth rasterizer, Worchel and Alexa's differentiable
  shadow map (lecture 12).
* ``fit``: a directional light's direction recovered from one shadowed image (lecture 12).
* ``art``: shadow art, a flat occluder deformed until its shadow draws a target outline (lecture 12).
* ``area``: soft shadows of polygonal area lights in closed form: the form factor of a partly hidden light
  (``light_form_factor``: the light clipped by the receiver's tangent plane and by the occluders' projections,
  Lambert's contour formula), differentiable, and the image it lights (lecture 14).
* ``penumbra``: the penumbra's gradient by the estimators a student meets (shadow rays, edge sampling, finite
  differences, variance shadow maps averaged over the light), against the exact one (lecture 14).
* ``area_fit``: an area light's position and size, and an occluder's shape, fitted to a picture of a soft
  shadow (lecture 14).

Exported here: every public name of ``maps`` (so ``course.shadows.shadow_map`` reads as it always has), and the
entry points of the others; the rest from their modules (``from course.shadows.gradients import
project_onto_plane``). Until 2026-11 these were the top-level modules ``course.shadows`` (now ``maps``),
``course.shadow_gradients``, ``course.prefiltered_shadows``, ``course.shadow_fit`` and ``course.shadow_art``;
the old names still import, with a warning that names the new place (``course._moved``).
"""
from .area import light_form_factor
from .area_fit import fit_area_light
from .art import fit_shadow_art
from .fit import fit_light_direction
from .gradients import shadow_image_gradient, shadow_scene, shadowed_coverage, split_by_shadows
from .maps import (CUBE_FACES, ShadowMap, SpotLight, area_light_samples, area_shadow_factor, biased_depth,
                   biased_lit, light_camera, light_space, pcf, shadow_factor, shadow_map)
from .penumbra import penumbra_gradient
from .prefiltered import shadow_map_image

__all__ = ["SpotLight", "ShadowMap", "CUBE_FACES", "light_camera", "shadow_map", "light_space", "biased_depth",
           "biased_lit", "pcf", "shadow_factor", "area_light_samples", "area_shadow_factor",
           "shadowed_coverage", "shadow_image_gradient", "split_by_shadows", "shadow_scene", "shadow_map_image",
           "fit_light_direction", "fit_shadow_art", "light_form_factor", "penumbra_gradient", "fit_area_light"]
