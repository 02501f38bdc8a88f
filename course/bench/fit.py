"""The inverse-rendering benchmark (lecture 10): ``python -m course bench fit
[--only mesh,images,camera,starts,texture,views,batch] [--fast] [--figure PNG]``.

Each application of lecture 10 is fitted once, with its entry point's defaults and seed 0, and reported as
steps, wall time and the final metric on held-out views next to its start value and the issue's target:

* **mesh**: ``course.inverse.fit_mesh_from_silhouettes(teapot, n_views=8)``, a sphere deformed to the teapot's
  silhouettes, again with the regulariser off (``smoothness=0``) to show what it is for, and with Nicolet et
  al.'s Large Steps (``optimizer="large_steps"``, λ = 5, no regulariser). Metrics: the held-out IoU, target
  >= 0.90; the fitted mesh's self-intersections (``course.inverse.self_intersections``, pairs of faces that cross
  each other; the start sphere has none), target 0; and in 3D against the teapot (``course.inverse.metrics``,
  20,000 samples a side): the Chamfer distance in percent of the bounding-box diagonal (target <= 0.5 %) and
  the normal consistency (target >= 0.93).
* **images**: ``course.inverse.fit_mesh_from_images(teapot)`` (12 shaded views at 64², the visual hull carved from
  their masks, then 150 steps of soft rasterization with Large Steps), and one change at a time
  (``IMAGE_FITS``): Adam on vertex offsets in place of Large Steps (same steps), with Kato et al.'s smoothness
  loss and without a regulariser; the sphere in place of the hull (300 steps); and both gradients for 20 steps,
  soft and ``"reynolds"`` (the exact box-filtered image and lecture 09's boundary gradient, too slow per step
  for the full budget here). Metrics: the held-out IoU, target >= 0.96; the held-out PSNR of the shaded images
  (30 dB, as for textures); and the three 3D metrics above, each row's start being its fit's start.
* **camera**: ``course.inverse.fit_camera`` on ``course.inverse.camera_problem()`` (the teapot, flat-shaded by a light
  fixed in the world, seen from a reference camera; the start 30° away about the world's vertical axis, not
  the view axis), once per gradient in ``course.inverse.CAMERA_METHODS`` (read at run time, so a new method joins
  by itself), each with ``fit_camera``'s defaults (soft and NMR search 7 starts; a row's start is
  ``camera_problem``'s); then the course's full pipeline as the reference, ``render()`` of the textured,
  Phong-lit teapot (``camera_problem(textured=True)``, the start orbited 45° about the world's x axis,
  ``TEXTURED_AXIS``: 39° of rotation, ``look_at`` keeping it upright), with the defaults and with one start
  on one image size (``starts=1, levels=1``). Metrics: the rotation error, target <= 2°, and the centre error,
  target <= 2 % of the viewing distance (two rows per fit, one time).
* **starts**: lecture 10's one-start camera fit (32², ``starts=1, levels=1``, 40 steps, learning rate 0.05) from
  six starts 20° away about different axes (``START_AXES``), for NMR, soft rasterization, soft rasterization at
  the pixel centres only (``supersample=1``) and Reynolds: the median rotation error at step 20 (the row's
  start) and 40, and how many starts end within 3°.
* **texture**: ``course.inverse.texture.fit_texture_from_images`` (the teapot's checker texture), and
  ``fit_vertex_colors_from_images`` against the same checker (vertex colours can only blur its edges: below
  the target by design) and against a smooth vertex-coloured target (``smooth_vertex_colors(teapot, 0)``).
  Metric: the held-out PSNR, target >= 30 dB.
* **views**: ``course.inverse.views.fit_with_learned_views(teapot)``, the views fixed on the ring
  (``learn_views=False``) and learned (``True``). Metric: the held-out IoU, target >= 0.90.
* **batch**: what a fit's step renders, the views one by one against one call for all of them (a camera batch),
  side by side in the same run (``timing.time_side_by_side``, the median of ``BATCH_REPEAT`` runs after a warm-up),
  on the teapot from ``sphere_views(N, offset=1.9)`` as the fits see it, for 12 views at 64² (the mesh from
  images) and 8 views at 32²: soft silhouettes with their gradient (σ = 3e-4, ``fit_silhouettes``' start),
  soft colours with their gradient (σ = 3e-5, γ = 1e-2, ``fit_mesh_from_images``), the exact image with
  the colours' gradient (``exact_coverage``, as ``inverse.shaded._reynolds_backward`` draws it) and the Reynolds gradient
  of the vertices (``image_gradient``). Two rows per case: the time in ms, one by one → batched (met when the
  batch is no slower), and the speed-up (one by one / batched); "steps" is the number of views, "time (s)"
  the whole measurement. ``--fast``: 4 views at 16² of ``teapot(3)``, one timed run.

The teapot is ``models.teapot(dtype=torch.float64)`` (``teapot(4)`` in ``camera_problem``). A fit is slow
(seconds to minutes), so each runs once (``REPEAT = 1``; ``--repeat`` is accepted and ignored), timed with
``time.perf_counter`` around the call, with ``progress=False``; a line per fit is printed as each application
finishes, then the table. ``--figure PNG`` also saves the mesh from images as target / start / result from two
views (the README's picture, ``save_fit_picture``). ``--fast`` runs every fit small (few steps, small images)
to check that the command works; its numbers are not the course's.
"""
from __future__ import annotations

import time

import torch

from .. import inverse as fit, models
from ..inverse import metrics as shape_metrics, texture as fit_texture, views as fit_views
from ..mesh import Mesh

__all__ = ["APPLICATIONS", "bench_fit", "save_fit_picture", "format_table", "add_arguments", "run"]

REPEAT = 1               # a fit takes seconds to a minute: each runs once
DESCRIPTION = ("lecture 10's fits (mesh, images, camera, texture, views): steps, time, final metric on held-out "
               "views; a camera batch against its views one by one (batch)")

APPLICATIONS = ("mesh", "images", "camera", "starts", "texture", "views", "batch")

# the targets: (better, target)
IOU_TARGET = ("higher", 0.90)
ROTATION_TARGET = ("lower", 2.0)            # degrees
CENTER_TARGET = ("lower", 2.0)              # percent of the reference's viewing distance
TEXTURED_AXIS = (1.0, 0.0, 0.0)             # the textured camera fit's start: 45° about the world's x axis
PSNR_TARGET = ("higher", 30.0)              # dB
NO_CROSSINGS = ("lower", 0)                 # pairs of faces of the fitted mesh that cross each other
CHAMFER_TARGET = ("lower", 0.5)             # percent of the target's bounding-box diagonal (shape_metrics)
NORMALS_TARGET = ("higher", 0.93)           # normal consistency (shape_metrics)
LARGE_STEPS = dict(optimizer="large_steps", lam=5.0, lr=0.02, smoothness=0.0)   # Nicolet et al.'s parameterization
IMAGE_IOU_TARGET = ("higher", 0.96)         # the mesh from images is held to more than the silhouette fit
# the mesh from images: its defaults, then one change at a time (the same budget unless the label says)
IMAGE_FITS = (("soft, large steps", {}),
              ("soft, Adam + smoothness 1e-4", dict(optimizer="adam", lr=0.002, smoothness=1e-4)),
              ("soft, Adam, no regulariser", dict(optimizer="adam", lr=0.002)),
              ("soft, large steps, from a sphere", dict(start="sphere", lr=0.02, steps=300)),
              ("soft, large steps, 20 steps", dict(steps=20)),
              ("reynolds, large steps, 20 steps", dict(gradient="reynolds", steps=20)))
BATCH_SIZES = ((12, 64), (8, 32))          # (views, pixels a side): the mesh from images', and smaller
BATCH_REPEAT = 3                           # timed runs of each side (the median), after one warm-up


# ------------------------------------------------------------------------------------------- helpers

def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    result = fn(*args, **kwargs)
    return result, time.perf_counter() - start


def _row(application, method, result, seconds, metric, unit, start, final, target):
    """A fit's row: its steps are those its history recorded (``_steps_row``)."""
    return _steps_row(application, method, len(result.history.loss), seconds, metric, unit, start, final, target)


def _steps_row(application, method, steps, seconds, metric, unit, start, final, target):
    better, goal = target
    final = None if final is None else float(final)
    met = final is not None and (final >= goal if better == "higher" else final <= goal)
    return dict(application=application, method=method, steps=steps, seconds=seconds,
                metric=metric, unit=unit, start=None if start is None else float(start), final=final,
                target=goal, better=better, met=bool(met))


# ------------------------------------------------------------------------------------- applications

def _mesh_rows(fast, out, figure=None):
    teapot = models.teapot(dtype=torch.float64)
    small = dict(n_views=4, size=32, steps=10, subdivisions=2) if fast else dict(n_views=8)
    rows = []
    samples = 2000 if fast else 20000
    for label, extra in (("soft", {}), ("soft, smoothness=0", dict(smoothness=0.0)),
                         ("soft, large steps", LARGE_STEPS)):
        r, s = _timed(fit.fit_mesh_from_silhouettes, teapot, seed=0, progress=False, **small, **extra)
        rows.append(_row("mesh", label, r, s, "held-out IoU", "", r.start_iou, r.iou, IOU_TARGET))
        start = Mesh(r.history.snapshots[0], r.mesh.faces)                  # what the regulariser is for
        rows.append(_row("mesh", label, r, s, "self-intersections", "pairs", len(fit.self_intersections(start)),
                         len(fit.self_intersections(r.mesh)), NO_CROSSINGS))
        before = shape_metrics.shape_metrics(start, teapot, samples=samples)
        after = shape_metrics.shape_metrics(r.mesh, teapot, samples=samples)
        rows.append(_row("mesh", label, r, s, "Chamfer (of the diagonal)", "%", 100 * before["chamfer"],
                         100 * after["chamfer"], CHAMFER_TARGET))
        rows.append(_row("mesh", label, r, s, "normal consistency", "", before["normal_consistency"],
                         after["normal_consistency"], NORMALS_TARGET))
    return rows


def _images_rows(fast, out, figure=None):
    """The mesh from shaded images: the default fit, then each change of ``IMAGE_FITS`` alone, every row's start
    being that fit's start (the carved hull, or the sphere). The data (``fit.shaded_data``: the exact targets, the
    hull, the held-out references) are computed once for all rows; a row's seconds are its fit's alone."""
    teapot = models.teapot(dtype=torch.float64)
    small = dict(n_views=4, size=32, resolution=24) if fast else {}
    samples = 2000 if fast else 20000
    data = fit.shaded_data(teapot, **small)             # the targets, hull and references: shared, in no row's time
    rows, judged = [], {}
    for k, (label, extra) in enumerate(IMAGE_FITS):
        extra = dict(extra, steps=min(extra.get("steps", 150), 3)) if fast else extra
        r, s = _timed(fit.fit_mesh_from_images, teapot, seed=0, progress=False, data=data, **extra)
        start = extra.get("start", "hull")                                   # one start, judged once
        if start not in judged:
            judged[start] = shape_metrics.shape_metrics(r.start, teapot, samples=samples)
        before = judged[start]
        after = shape_metrics.shape_metrics(r.mesh, teapot, samples=samples)
        for metric, unit, start, final, target in (
                ("held-out IoU", "", r.start_iou, r.iou, IMAGE_IOU_TARGET),
                ("held-out PSNR", "dB", r.start_psnr, r.psnr, PSNR_TARGET),
                ("self-intersections", "pairs", before["self_intersections"], after["self_intersections"],
                 NO_CROSSINGS),
                ("Chamfer (of the diagonal)", "%", 100 * before["chamfer"], 100 * after["chamfer"], CHAMFER_TARGET),
                ("normal consistency", "", before["normal_consistency"], after["normal_consistency"],
                 NORMALS_TARGET)):
            rows.append(_row("images", label, r, s, metric, unit, start, final, target))
        if figure and k == 0:                                                # the defaults: the README's picture
            save_fit_picture(teapot, r, figure)
            out(f"wrote {figure}")
    return rows


def save_fit_picture(target, result, path, size: int = 256):
    """The README's picture of the mesh from images: the target (untextured), the start (the carved hull) and
    the result, shaded, from two views that are not training views: three-quarters from above (eye (2, 1.3,
    1.9), the hollow round the lid) and from the side (eye (0, 0.25, 3), the hole of the handle), captioned
    with the held-out metrics."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..camera import Camera
    from ..viz.fit import image_to_frame, mesh_renderer
    eyes = ((2.0, 1.3, 1.9), (0.0, 0.25, 3.0))
    items = ((target, "target"), (result.start, f"start: the visual hull\nheld-out IoU {result.start_iou:.3f}, "
                                                 f"PSNR {result.start_psnr:.1f} dB"),
             (result.mesh, f"result: {len(result.history.loss)} steps\nheld-out IoU {result.iou:.3f}, "
                           f"PSNR {result.psnr:.1f} dB"))
    fig, axes = plt.subplots(2, 3, figsize=(9, 6.6))
    for row, eye in enumerate(eyes):
        camera = Camera.look_at(eye, fov_y=40, width=size, height=size, dtype=torch.float64)
        draw = mesh_renderer(result.mesh.faces, camera)
        for col, (mesh, title) in enumerate(items):
            axes[row, col].imshow(image_to_frame(draw(Mesh(mesh.verts, mesh.faces))))
            axes[row, col].axis("off")
            if row == 0:
                axes[row, col].set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def _camera_rows(fast, out, figure=None):
    mesh, colors, ref_cam, start, ref_image = fit.camera_problem(size=24 if fast else 64)
    rows = []
    for method in fit.CAMERA_METHODS:
        r, s = _timed(fit.fit_camera, mesh, ref_image, start, method=method, face_colors=colors,
                      reference_camera=ref_cam, progress=False, seed=0, **(dict(steps=5) if fast else {}))
        # the start's own errors (the history starts where the search's winner did)
        rows.append(_row("camera", method, r, s, "rotation error", "deg", fit.rotation_error(start.R, ref_cam.R),
                         r.rotation_error_deg, ROTATION_TARGET))
        rows.append(_row("camera", method, r, s, "centre error", "%", fit.center_error(start, ref_cam),
                         r.center_error_pct, CENTER_TARGET))
    _, scene, ref_cam, start, ref_image = fit.camera_problem(size=24 if fast else 64, degrees=45.0,
                                                             axis=TEXTURED_AXIS, textured=True)
    for name, options in (("soft, render() reference, defaults", {}),
                          ("soft, render() reference, one start", dict(starts=1, levels=1))):
        r, s = _timed(fit.fit_camera, scene, ref_image, start, reference_camera=ref_cam, progress=False,
                      **options, **(dict(steps=5) if fast else {}))
        rows.append(_row("camera", name, r, s, "rotation error", "deg", fit.rotation_error(start.R, ref_cam.R),
                         r.rotation_error_deg, ROTATION_TARGET))
        rows.append(_row("camera", name, r, s, "centre error", "%", fit.center_error(start, ref_cam),
                         r.center_error_pct, CENTER_TARGET))
    return rows


START_AXES = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.3, 1.0, -0.5), (-1.0, 0.5, 0.5),
              (0.0, 0.3, 1.0))                                  # the six starts' axes, 20° each (lecture 10)
START_VARIANTS = {"nmr": dict(method="nmr"), "soft": dict(method="soft"),
                  "soft, pixel centres": dict(method="soft", supersample=1), "reynolds": dict(method="reynolds")}


def _starts_rows(fast, out, figure=None):
    """Lecture 10's one-start camera fit repeated from six starts 20° away about different axes (32², one start,
    one level, 40 steps, lr 0.05): per variant, the median rotation error at step 40 (start: at step 20) and how
    many of the six end within 3°."""
    size, steps, axes = (16, 6, START_AXES[:2]) if fast else (32, 40, START_AXES)      # --fast: two starts
    mesh, colors, reference, _, target = fit.camera_problem(models.teapot(3), size=size)
    starts = [fit.camera_problem(models.teapot(3), size=size, degrees=20.0, axis=a)[3] for a in axes]
    rows = []
    for name, options in START_VARIANTS.items():
        paths, seconds = [], 0.0
        for s in starts:
            r, t = _timed(fit.fit_camera, mesh, target, s, steps=steps, lr=0.05, starts=1, levels=1,
                          face_colors=colors, reference_camera=reference, snapshot_every=None, progress=False,
                          **options)
            paths.append(r.history.metrics["rotation_deg"])
            seconds += t
        middle, last = sorted(p[steps // 2] for p in paths), sorted(p[steps] for p in paths)
        rows.append(_steps_row("starts", name, steps, seconds, "median rotation error (start: at step "
                               f"{steps // 2})", "deg", middle[len(middle) // 2], last[len(last) // 2],
                               ("lower", 3.0)))
        rows.append(_steps_row("starts", name, steps, seconds, "starts within 3°", f"of {len(starts)}",
                               sum(p[0] <= 3 for p in paths), sum(e <= 3 for e in last), ("higher", len(starts))))
    return rows


def _texture_rows(fast, out, figure=None):
    small = dict(steps=10, size=32) if fast else {}
    r, s = _timed(fit_texture.fit_texture_from_images, seed=0, progress=False, **small)
    rows = [_row("texture", "texture, checker target", r, s, "held-out PSNR", "dB", r.start_psnr, r.psnr,
                 PSNR_TARGET)]
    smooth = fit_texture.smooth_vertex_colors(models.teapot(dtype=torch.float64), 0)
    for label, extra in (("vertex colours, checker target", {}),            # can only blur the checker's edges
                         ("vertex colours, vertex-coloured target", dict(target_colors=smooth))):
        r, s = _timed(fit_texture.fit_vertex_colors_from_images, seed=0, progress=False, **small, **extra)
        rows.append(_row("texture", label, r, s, "held-out PSNR", "dB", r.start_psnr, r.psnr, PSNR_TARGET))
    return rows


def _views_rows(fast, out, figure=None):
    teapot = models.teapot(dtype=torch.float64)
    small = dict(n_views=4, size=32, steps=8, subdivisions=2) if fast else {}
    rows = []
    for learn in (False, True):
        r, s = _timed(fit_views.fit_with_learned_views, teapot, learn_views=learn, seed=0, progress=False, **small)
        rows.append(_row("views", "learned views" if learn else "ring (fixed)", r, s, "held-out IoU", "",
                         r.start_iou, r.iou, IOU_TARGET))
    return rows


def _batch_cases(mesh):
    """(label, draw) for each renderer a fit's step calls: ``draw(cameras, weights)`` runs it and the gradient
    of ``Σ weights ⊙ image`` (the vertices', or the colours' for the exact image) on one camera, weights
    (H, W, 3), or on a list of N, weights (N, H, W, 3), in one call (a camera batch)."""
    from ..coverage import exact_coverage
    from ..soft import soft_rasterize
    from ..visibility import image_gradient
    colors = fit.shaded_face_colors(mesh)

    def silhouettes(cameras, weights):
        verts = mesh.verts.clone().requires_grad_()
        image = soft_rasterize(Mesh(verts, mesh.faces), cameras, mode="silhouette", sigma=3e-4,
                               cull_backfaces=False)
        torch.autograd.grad((weights[..., 0] * image).sum(), verts)

    def colours(cameras, weights):
        verts = mesh.verts.clone().requires_grad_()
        image = soft_rasterize(Mesh(verts, mesh.faces), cameras, mode="color", sigma=3e-5, gamma=1e-2,
                               face_colors=colors, background=fit.SKY)
        torch.autograd.grad((weights * image).sum(), verts)

    def exact(cameras, weights):
        leaf = colors.clone().requires_grad_()
        torch.autograd.grad((weights * exact_coverage(mesh, cameras, leaf, fit.SKY)).sum(), leaf)

    def reynolds(cameras, weights):
        image_gradient(mesh, cameras, colors, weights, method="reynolds", background=fit.SKY)
    return (("soft silhouettes + gradient", silhouettes), ("soft colours + gradient", colours),
            ("exact image + colour gradient", exact), ("Reynolds gradient", reynolds))


def _batch_rows(fast, out, figure=None):
    """Each renderer of a fit's step, the views one by one against one batched call (module docstring)."""
    from .timing import time_side_by_side
    mesh = models.teapot(3 if fast else 8, dtype=torch.float64)
    rows = []
    for n, size in ((4, 16),) if fast else BATCH_SIZES:
        cameras = fit.sphere_views(n, offset=1.9, size=size, dtype=torch.float64)
        weights = torch.randn(n, size, size, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
        for label, draw in _batch_cases(mesh):
            start = time.perf_counter()
            one, batched = time_side_by_side([lambda: [draw(c, w) for c, w in zip(cameras, weights)],
                                              lambda: draw(cameras, weights)],
                                             repeat=1 if fast else BATCH_REPEAT)
            seconds = time.perf_counter() - start
            method = f"{label}, {n} views at {size}²"
            rows.append(_steps_row("batch", method, n, seconds, "time, one by one -> batched", "ms", one, batched,
                                   ("lower", one)))
            rows.append(_steps_row("batch", method, n, seconds, "speed-up", "x", 1.0, one / batched, ("higher", 1.0)))
    return rows


RUNNERS = {"mesh": _mesh_rows, "images": _images_rows, "camera": _camera_rows, "starts": _starts_rows,
           "texture": _texture_rows, "views": _views_rows, "batch": _batch_rows}


def bench_fit(only=APPLICATIONS, fast: bool = False, out=print, figure=None) -> list[dict]:
    """Run the fits of the applications in ``only`` (names of ``APPLICATIONS``) once each; returns one row
    (dict) per fit and metric: application, method, steps, seconds, metric, unit, start, final, target,
    better ("higher" / "lower"), met. Prints a line per row as each application finishes (a full run takes
    minutes), then the rows as a markdown table. figure: a path for ``save_fit_picture`` of the mesh from
    images (it runs only with "images" in ``only``)."""
    unknown = [a for a in only if a not in APPLICATIONS]
    if unknown:
        raise ValueError(f"unknown application(s) {unknown}; choose from {', '.join(APPLICATIONS)}")
    rows = []
    for app in only:
        new = RUNNERS[app](fast, out, figure)
        for r in new:
            out(f"{app} / {r['method']}: {r['metric']} {_num(r['start'], r['unit'])} -> {_num(r['final'], r['unit'])}"
                f" in {r['steps']} steps, {r['seconds']:.1f} s")
        rows += new
    out(format_table(rows))
    return rows


def _num(v, unit):
    if v is None:
        return "–"
    if unit == "":
        return f"{v:.3f}"
    if unit in ("pairs", "of 6"):
        return f"{v:.0f}"
    return f"{v:.2f}{' ' + unit if unit != '%' else unit}"


def format_table(rows) -> str:
    """The rows as a markdown table."""
    lines = ["| application | method | steps | time (s) | metric | start | final | target | met |",
             "|---|---|--:|--:|---|--:|--:|--:|:-:|"]
    for r in rows:
        goal = f"{'≥' if r['better'] == 'higher' else '≤'} {_num(r['target'], r['unit'])}"
        lines.append(f"| {r['application']} | {r['method']} | {r['steps']} | {r['seconds']:.1f} | {r['metric']} | "
                     f"{_num(r['start'], r['unit'])} | {_num(r['final'], r['unit'])} | {goal} | "
                     f"{'yes' if r['met'] else 'no'} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- the command's options

def _applications(text: str) -> list[str]:
    names = [a.strip() for a in text.split(",") if a.strip()]
    bad = [a for a in names if a not in APPLICATIONS]
    if bad or not names:
        import argparse
        raise argparse.ArgumentTypeError(f"unknown application(s) {bad or text!r}; choose from "
                                         f"{','.join(APPLICATIONS)}")
    return names


def add_arguments(parser) -> None:
    """The options of ``python -m course bench fit``."""
    parser.add_argument("--only", type=_applications, default=list(APPLICATIONS),
                        help=f"comma-separated applications (default: all of {','.join(APPLICATIONS)})")
    parser.add_argument("--fast", action="store_true",
                        help="tiny fits (few steps, small images): checks the command, not the course's numbers")
    parser.add_argument("--figure", metavar="PNG",
                        help="also save the mesh from images' target / start / result picture there "
                             "(docs/fit_teapot.png)")


def run(args) -> list[dict]:
    return bench_fit(args.only, args.fast, figure=args.figure)
