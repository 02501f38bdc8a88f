"""Style: texture statistics of an image, and a mesh's colours and shape changed to match them (lecture 11).

* ``features``: the style of an image as statistics: Gram matrices of the feature maps of a seeded
  network of random filters (Gatys et al.'s style loss, with Ustyuzhaninov et al.'s random features in place
  of a trained VGG), 2D texture synthesis from them, and the bundled style images (``stripes``, ``dots``,
  ``marble``).
* ``transfer``: Kato et al.'s 2D-to-3D style transfer and 3D DeepDream through the renderer (soft or hard),
  views uniform on the sphere, judged on held-out views.

Exported here: every public name of ``features`` (so ``course.style.gram_matrix`` reads as it always has),
and the entry points of ``transfer``. ``course.stylize``, the old top-level name of ``transfer``, still imports,
with a warning that names the new place (``course._moved``).
"""
from .features import RandomFeatures, dots, gram_matrix, marble, stripes, style_loss, synthesize_texture
from .transfer import deep_dream_mesh, random_directions, stylize_mesh

__all__ = ["RandomFeatures", "gram_matrix", "style_loss", "synthesize_texture", "stripes", "dots", "marble",
           "stylize_mesh", "deep_dream_mesh", "random_directions"]
