"""The learning benchmark: ``python -m course bench learn [--quick] [--save FILE] [--parts ...]``.

Two questions of lecture 13, each answered by training from scratch on the CPU (about 6 minutes at the
defaults with one thread on a quiet machine, about twice that when other jobs share the cores; the
reconstruction is 3 to 8 of them, MVTN 3 to 5; ``--quick`` runs a tiny version of everything in seconds):

* **reconstruction** (Kato et al. 2018's Table 1, made here): ``learn.train_reconstructor`` on
  ``--n-train`` shapes of each of the six training families, rendered from ``--views`` views (input view 0,
  a random pair of views per shape and step as targets), then ``learn.evaluate_reconstruction`` on
  ``--n-test`` new shapes per family and on the held-out torus: voxel IoU at 32³ and Chamfer distance
  (a fraction of the target's diagonal) of the network, of retrieval (the training shape with the nearest
  input image) and of the untrained sphere. ``--save FILE`` writes the trained network (float32 weights,
  ``learn.save_reconstructor``).
* **mvtn** (Hamdi et al. 2021): ``mvtn.train_mvtn`` classifies the six families from ``--mvtn-views``
  soft silhouettes, with the views fixed on a circle and learned through the renderer (``--mvtn-modes``:
  also "predicted", a view per object from its points, MVTN proper), over ``--mvtn-seeds``: test accuracy
  mean ± spread (half the range) and the learned view directions.

It prints a table per part and returns the rows (one per family and method; one per MVTN run).
"""
from __future__ import annotations

import time

import torch

from ..learning.reconstruction import ReconstructionSettings, evaluate_reconstruction, save_reconstructor, train_reconstructor
from ..learning.data import make_splits

__all__ = ["bench_reconstruction", "bench_mvtn", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("learning through the renderer: single-image reconstruction against retrieval and a sphere "
               "(voxel IoU, Chamfer), and MVTN's learned views against fixed ones (accuracy)")
QUICK = dict(n_train=4, n_test=2, views=4, steps=4, batch=4, mvtn_train=4, mvtn_test=2, mvtn_steps=3,
             mvtn_seeds=[0])


def bench_reconstruction(n_train=100, n_test=20, views=8, steps=1200, batch=16, lr=2e-3, seed=0, save=None,
                         progress=True) -> list:
    """Train, evaluate and print the per-family table; returns its rows (``evaluate_reconstruction``'s)."""
    settings = ReconstructionSettings(seed=seed)
    t0 = time.perf_counter()
    splits = make_splits(n_train, 1, n_test, views=views, size=settings.size, dtype=torch.float32, seed=seed,
                         progress=progress)
    t_data = time.perf_counter() - t0
    model, losses = train_reconstructor(splits["train"], settings=settings, steps=steps, batch=batch, views=2,
                                        lr=lr, seed=seed, progress=progress)
    t_train = time.perf_counter() - t0 - t_data
    rows = []
    for split in ("test", "held_out"):
        rows += evaluate_reconstruction(model, splits["train"], splits[split], split=split, progress=progress)
    t_all = time.perf_counter() - t0
    head = min(len(losses), 50)
    print(f"reconstruction: {n_train} training shapes per family x {len(splits['train'].families)} families, "
          f"{views} views at {settings.size} px, {steps} steps of {batch} shapes (random view pairs), Adam lr "
          f"{lr:g} cosine; loss {sum(losses[:head]) / max(head, 1):.3f} (first 50) -> "
          f"{sum(losses[-head:]) / max(head, 1):.3f} (last 50)")
    print(f"time: data {t_data:.0f} s, training {t_train:.0f} s, evaluation {t_all - t_data - t_train:.0f} s")
    print("voxel IoU at 32^3 (higher is better) and Chamfer distance / target diagonal (lower is better), input "
          "view 0")
    print(f"{'split':<9} {'family':<9} {'n':>3} | {'IoU net':>7} {'retr.':>6} {'sphere':>6} | "
          f"{'CD net':>7} {'retr.':>6} {'sphere':>6}")
    for r in rows:
        if r["family"] == "mean" and sum(q["split"] == r["split"] for q in rows) == 2:
            continue                                                   # one family: its mean is its row
        print(f"{r['split']:<9} {r['family']:<9} {r['n']:>3} | {r['iou_network']:>7.3f} {r['iou_retrieval']:>6.3f} "
              f"{r['iou_sphere']:>6.3f} | {r['chamfer_network']:>7.4f} {r['chamfer_retrieval']:>6.4f} "
              f"{r['chamfer_sphere']:>6.4f}")
    if save:
        mean = next(r for r in rows if r["split"] == "test" and r["family"] == "mean")
        note = (f"python -m course bench learn --save (n_train={n_train}, views={views}, steps={steps}, "
                f"batch={batch}, lr={lr:g}, seed={seed}); test voxel IoU {mean['iou_network']:.3f} (retrieval "
                f"{mean['iou_retrieval']:.3f}, sphere {mean['iou_sphere']:.3f})")
        save_reconstructor(model, save, note)
        print(f"checkpoint written to {save}: {note}")
    return rows


def bench_mvtn(n_train=40, n_test=20, views=4, steps=150, seeds=(0, 1, 2), modes=("fixed", "learned"),
               progress=True, plot=None) -> list:
    """Fixed against learned (and predicted) views over ``seeds``: train, test, print; returns one row per
    (mode, seed) with the accuracy and the views (for "predicted": their mean over the test shapes). plot: a
    file for ``mvtn.plot_view_directions`` of every run's views."""
    from ..learning.mvtn import MVTNSettings, evaluate_mvtn, make_mvtn_data, plot_view_directions, train_mvtn
    t0 = time.perf_counter()
    train, test = make_mvtn_data(n_train, n_test, seed=0)
    rows = []
    for mode in modes:
        for seed in seeds:
            t1 = time.perf_counter()
            model, _ = train_mvtn(train, settings=MVTNSettings(views=views, mode=mode, seed=seed), steps=steps,
                                  seed=seed, progress=progress)
            accuracy = evaluate_mvtn(model, test)
            with torch.no_grad():
                az, el = model.view_angles(test.meshes if mode == "predicted" else None)
            spread = float(az.std(0).mean()) if az.ndim == 2 else 0.0  # per-object views: how much they differ
            az, el = (az.mean(0), el.mean(0)) if az.ndim == 2 else (az, el)
            rows.append(dict(part="mvtn", mode=mode, seed=seed, accuracy=accuracy, seconds=time.perf_counter() - t1,
                             azimuths=[round(a, 1) for a in az.tolist()],
                             elevations=[round(e, 1) for e in el.tolist()], azimuth_spread=round(spread, 1)))
    print(f"\nMVTN: {len(train) // len(train.families)} training / {n_test} test shapes per family, {views} "
          f"soft silhouettes at 32 px, {steps} steps of 24; {time.perf_counter() - t0:.0f} s")
    print(f"{'views':<10} {'accuracy (mean ± half range)':<30} per seed")
    for mode in modes:
        acc = [r["accuracy"] for r in rows if r["mode"] == mode]
        spread = (max(acc) - min(acc)) / 2
        print(f"{mode:<10} {sum(acc) / len(acc):.3f} ± {spread:.3f}{'':<16} " + " ".join(f"{a:.3f}" for a in acc))
    for r in rows:
        if r["mode"] != "fixed":
            extra = f" (mean over test shapes; azimuth sd {r['azimuth_spread']})" if r["mode"] == "predicted" else ""
            print(f"{r['mode']} views, seed {r['seed']}: azimuth {r['azimuths']} deg, elevation {r['elevations']} "
                  f"deg{extra}")
    if plot:
        runs = [r for r in rows if r["mode"] != "fixed" or r["seed"] == seeds[0]]
        plot_view_directions({f"{r['mode']}" + (f" seed {r['seed']}" if r["mode"] != "fixed" else ""):
                              (torch.tensor(r["azimuths"]), torch.tensor(r["elevations"])) for r in runs}, plot)
        print(f"view directions drawn in {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--parts", choices=("both", "reconstruction", "mvtn"), default="both",
                        help="which benchmark to run (default both, 6 to 13 minutes on one core)")
    parser.add_argument("--quick", action="store_true", help="a tiny run of everything (seconds): a smoke test")
    parser.add_argument("--n-train", type=int, default=100, help="reconstruction: training shapes per family")
    parser.add_argument("--n-test", type=int, default=20, help="reconstruction: test shapes per family")
    parser.add_argument("--views", type=int, default=8, help="reconstruction: rendered views per shape")
    parser.add_argument("--steps", type=int, default=1200, help="reconstruction: training steps")
    parser.add_argument("--batch", type=int, default=16, help="reconstruction: shapes per step")
    parser.add_argument("--lr", type=float, default=2e-3, help="reconstruction: Adam's initial learning rate")
    parser.add_argument("--seed", type=int, default=0, help="reconstruction: data, weights and order")
    parser.add_argument("--save", default="", help="write the trained reconstructor here ('' for nowhere)")
    parser.add_argument("--mvtn-train", type=int, default=40, help="MVTN: training shapes per family")
    parser.add_argument("--mvtn-test", type=int, default=20, help="MVTN: test shapes per family")
    parser.add_argument("--mvtn-views", type=int, default=4, help="MVTN: views per shape")
    parser.add_argument("--mvtn-steps", type=int, default=150, help="MVTN: training steps")
    parser.add_argument("--mvtn-seeds", nargs="+", type=int, default=[0, 1, 2], help="MVTN: seeds (weights)")
    parser.add_argument("--mvtn-modes", nargs="+", choices=("fixed", "sphere", "learned", "predicted"),
                        default=["fixed", "learned"], help="MVTN: how the views are chosen (predicted: per object, "
                                                           "about 4 more minutes)")
    parser.add_argument("--plot", default="", help="MVTN: draw the view directions on a sphere in this file")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args) -> list[dict]:
    if getattr(args, "quick", False):
        for key, value in QUICK.items():
            setattr(args, key, value)
    progress = not getattr(args, "no_progress", False)
    rows = []
    if args.parts in ("both", "reconstruction"):
        rows += bench_reconstruction(args.n_train, args.n_test, args.views, args.steps, args.batch, args.lr,
                                     args.seed, args.save or None, progress)
    if args.parts in ("both", "mvtn"):
        rows += bench_mvtn(args.mvtn_train, args.mvtn_test, args.mvtn_views, args.mvtn_steps, args.mvtn_seeds,
                           args.mvtn_modes, progress, getattr(args, "plot", "") or None)
    return rows
