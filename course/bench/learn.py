"""The learning benchmark: ``python -m course bench learn [--quick] [--parts all|table|mvtn|diversity] [--save FILE]``.

Lecture 13's questions, each answered by training from scratch on the CPU (about 15 minutes at the defaults on
2 cores; ``--quick`` runs a tiny version of everything in seconds):

* **table** (Kato et al. 2018's Table 1, made on the course's families): the mesh network
  (``reconstruction.train_reconstructor``) and the voxel network (``voxels.train_voxel_reconstructor``), trained
  on the same batches of ``--n-train`` shapes of each of the six training families rendered from ``--views``
  views, then scored with every row of ``learning.table`` (retrieval, clustering, the oracle nearest training
  shape, the sphere) on ``--n-test`` new shapes per family and on the held-out torus: voxel IoU at 32³,
  point-to-surface Chamfer and the F-score at ``--fscore``, per family, each row paired against the mesh
  network (mean difference ± standard error over the shapes). Once for each input protocol (``--protocols``:
  view 0 of every shape, as lecture 13 once had it, and any view, as Kato et al.), each followed by the test
  shapes split by how near their nearest training twin is (``table.novelty_rows``). ``--save`` and
  ``--save-voxel`` write the two networks trained on inputs from any view (the shipped checkpoints).
* **diversity**: the mesh network against retrieval and the oracle as the training set shrinks
  (``--diversity-n`` shapes per family, inputs from any view, no voxel network).
* **mvtn** (Hamdi et al. 2021): ``mvtn.train_mvtn`` classifies the six families from ``--mvtn-views`` soft
  silhouettes with the views on a fixed circle, on a fixed sphere, learned once for all shapes, or predicted
  per shape from its points (MVTN proper), the same recipe for every mode, over ``--mvtn-seeds``; the shapes
  turned by random rotations (``--mvtn-rotated``; upright too on request): accuracy mean ± standard error over
  the seeds and the views each run ends with.

It prints a table per part and returns the rows (one per family, split, protocol and method; one per novelty
group; one per MVTN run).
"""
from __future__ import annotations

import time

import torch

from ..learning.reconstruction import ReconstructionSettings, save_reconstructor, train_reconstructor
from ..learning.data import make_splits
from ..learning.mvtn import MODES

__all__ = ["bench_table", "bench_diversity", "bench_mvtn", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("learning through the renderer: single-image reconstruction against retrieval and a sphere "
               "(voxel IoU, Chamfer), and MVTN's learned views against fixed ones (accuracy)")
QUICK = dict(n_train=4, n_test=2, views=4, steps=4, batch=4, mvtn_train=4, mvtn_test=2, mvtn_steps=3, mvtn_batch=8,
             mvtn_seeds=[0, 1], clusters=4, diversity_n=[2, 3], protocols=["all"])


def bench_mvtn(n_train=40, n_test=20, views=4, steps=100, seeds=(0, 1, 2, 3, 4), modes=MODES, progress=True,
               plot=None, rotations=(True,), batch=16) -> list:
    """Fixed against learned (and predicted) views over ``seeds``: train, test, print; returns one row per
    (mode, seed) with the accuracy and the views (for "predicted": their mean over the test shapes). plot: a
    file for ``mvtn.plot_view_directions`` of every run's views."""
    rows = []
    for rotate in rotations:
        rows += _bench_mvtn_once(n_train, n_test, views, steps, seeds, modes, progress,
                                 plot if rotate == rotations[0] else None, rotate, batch)
    return rows


def _bench_mvtn_once(n_train, n_test, views, steps, seeds, modes, progress, plot, rotate, batch) -> list:
    from ..learning.mvtn import MVTNSettings, evaluate_mvtn, make_mvtn_data, plot_view_directions, train_mvtn
    t0 = time.perf_counter()
    train, test = make_mvtn_data(n_train, n_test, seed=0, rotate=rotate)
    rows = []
    for mode in modes:
        for seed in seeds:
            t1 = time.perf_counter()
            model, _ = train_mvtn(train, settings=MVTNSettings(views=views, mode=mode, seed=seed), steps=steps,
                                  batch=batch, seed=seed, progress=progress)
            accuracy = evaluate_mvtn(model, test)
            with torch.no_grad():
                az, el = model.view_angles(test.meshes if mode == "predicted" else None)
            spread = float(az.std(0).mean()) if az.ndim == 2 else 0.0  # per-object views: how much they differ
            az, el = (az.mean(0), el.mean(0)) if az.ndim == 2 else (az, el)
            rows.append(dict(part="mvtn", mode=mode, seed=seed, rotated=rotate, accuracy=accuracy,
                             seconds=time.perf_counter() - t1,
                             azimuths=[round(a, 1) for a in az.tolist()],
                             elevations=[round(e, 1) for e in el.tolist()], azimuth_spread=round(spread, 1)))
    print(f"\nMVTN: {len(train) // len(train.families)} training / {n_test} test shapes per family"
          f"{', each turned by its own random rotation' if rotate else ', upright'}, {views} soft silhouettes at "
          f"32 px, {steps} steps of {batch}, the same recipe for every mode; {time.perf_counter() - t0:.0f} s")
    print(f"{'views':<10} {'accuracy (mean ± standard error over seeds)':<44} per seed")
    for mode in modes:
        acc = torch.tensor([r["accuracy"] for r in rows if r["mode"] == mode], dtype=torch.float64)
        se = float(acc.std(unbiased=True)) / len(acc) ** 0.5 if len(acc) > 1 else float("nan")
        print(f"{mode:<10} {float(acc.mean()):.3f} ± {se:.3f}{'':<30} " + " ".join(f"{a:.3f}" for a in acc.tolist()))
    base = torch.tensor([r["accuracy"] for r in rows if r["mode"] == modes[0]], dtype=torch.float64)
    for mode in modes[1:]:                                             # the same seed: the same start and batches
        d = torch.tensor([r["accuracy"] for r in rows if r["mode"] == mode], dtype=torch.float64) - base
        se = float(d.std(unbiased=True)) / len(d) ** 0.5 if len(d) > 1 else float("nan")
        print(f"{mode} - {modes[0]}, paired by seed: {float(d.mean()):+.3f} ± {se:.3f}")
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


def _predictions(mesh_net, voxel_net, train, test, protocol, seed, lookups):
    """Every row's predictions for the ShapeSet ``test`` with inputs chosen by ``protocol``."""
    from ..learning.table import input_views, oracle_shapes, retrieve_shape
    from ..learning.voxels import voxel_mesh
    from ..mesh import Mesh
    views = input_views(test, protocol, seed=seed + 1)
    images = test.images[torch.arange(len(test)), views]
    train_grids, labels, representatives, test_grids = lookups
    nearest = retrieve_shape(train, images, protocol)
    with torch.no_grad():
        verts = mesh_net(images.to(mesh_net.template.dtype))
        occupancy = voxel_net(images.to(voxel_net.template.dtype)) if voxel_net is not None else None
    out = {"mesh": [Mesh(v, mesh_net.faces) for v in verts]}
    if occupancy is not None:
        out["voxel"] = [(o > 0.5, voxel_mesh(o)) for o in occupancy]
    out["retrieval"] = [(int(k), train.meshes, train_grids) for k in nearest]
    out["clustering"] = [(int(representatives[labels[k]]), train.meshes, train_grids) for k in nearest]
    out["oracle"] = [(int(k), train.meshes, train_grids) for k in oracle_shapes(torch.stack(train_grids),
                                                                                torch.stack(test_grids))]
    out["sphere"] = [Mesh(mesh_net.template, mesh_net.faces)] * len(test)
    return out


def _print_table(rows, title):
    from ..learning.table import METHODS
    methods = [m for m in METHODS if f"iou_{m}" in rows[0]]
    print(title)
    print("voxel IoU at 32^3 per family; each method's mean, then (for the others) its paired difference from the "
          "mesh network +- standard error")
    head = f"{'split':<9} {'family':<9} {'n':>3} | " + " ".join(f"{m:>19}" for m in methods)
    print(head)
    for metric in ("iou", "chamfer", "fscore"):
        if metric != "iou":
            print(f"  {metric}:")
        for r in rows:
            if r["family"] == "mean" and sum(q["split"] == r["split"] for q in rows) == 2:
                continue                                               # one family: its mean is its row
            cells = []
            for m in methods:
                value = r[f"{metric}_{m}"]
                if m == "mesh":
                    cells.append(f"{value:>19.3f}")
                else:
                    cells.append(f"{value:6.3f} {r[f'{metric}_{m}_diff']:+.3f}±{r[f'{metric}_{m}_se']:.3f}".rjust(19))
            print(f"{r['split']:<9} {r['family']:<9} {r['n']:>3} | " + " ".join(cells))


def _print_novelty(rows):
    methods = [m for m in ("voxel", "retrieval", "oracle") if f"iou_{m}" in rows[0]]
    print("test shapes by their nearest training twin (the oracle's IoU), farthest first: mean voxel IoU; the others "
          "as their difference from the mesh network +- standard error")
    print(f"{'oracle IoU':<13} {'n':>3} | {'mesh':>6} " + " ".join(f"{m:>19}" for m in methods))
    for r in rows:
        print(f"{r['oracle_low']:.3f}-{r['oracle_high']:.3f}  {r['n']:>3} | {r['iou_mesh']:6.3f} " + " ".join(
            f"{r[f'iou_{m}']:6.3f} {r[f'iou_{m}_diff']:+.3f}±{r[f'iou_{m}_se']:.3f}".rjust(19) for m in methods))


def bench_table(n_train=100, n_test=20, views=24, steps=800, batch=16, lr=2e-3, seed=0, protocols=("first", "all"),
                clusters=30, voxels=True, threshold=0.05, save=None, save_voxel=None, progress=True) -> list:
    """Kato et al.'s Table 1 on the course's families under each input protocol: train the mesh network and the
    voxel network on the same batches (``reconstruction.training_batches``), score every row of
    ``learning.table`` on the test families and the held-out torus, print per-family means with paired
    standard errors against the mesh network; returns the rows (with ``protocol`` and seconds per part)."""
    from ..learning.data import voxelize
    from ..learning.table import cluster_shapes, novelty_rows, score_predictions, table_rows
    from ..learning.voxels import VoxelSettings, save_voxel_reconstructor, train_voxel_reconstructor
    settings = ReconstructionSettings(seed=seed)
    t0 = time.perf_counter()
    splits = make_splits(n_train, 1, n_test, views=views, size=settings.size, dtype=torch.float32, seed=seed,
                         progress=progress)
    train = splits["train"]
    train_grids = [voxelize(m, 32) for m in train.meshes]
    labels, representatives = cluster_shapes(torch.stack(train_grids), min(clusters, len(train)), seed=seed)
    grids = {split: [voxelize(m, 32) for m in splits[split].meshes] for split in ("test", "held_out")}
    print(f"Table 1: {n_train} training shapes per family x {len(train.families)} families, {views} views at "
          f"{settings.size} px (30 deg up, azimuths a golden angle apart), {steps} steps of {batch} shapes, "
          f"Adam lr {lr:g} cosine; clustering k = {min(clusters, len(train))}; F-score at {threshold:g}; "
          f"data, voxels and clusters {time.perf_counter() - t0:.0f} s")
    rows = []
    for protocol in protocols:
        t1 = time.perf_counter()
        mesh_net, _ = train_reconstructor(train, settings=settings, steps=steps, batch=batch, views=2, lr=lr,
                                          seed=seed, input_views=protocol, progress=progress)
        t_mesh = time.perf_counter() - t1
        voxel_net = None
        if voxels:
            voxel_net, _ = train_voxel_reconstructor(train, settings=VoxelSettings(seed=seed), steps=steps,
                                                     batch=batch, views=2, lr=lr, input_views=protocol, seed=seed,
                                                     progress=progress)
        t_voxel = time.perf_counter() - t1 - t_mesh
        part = []
        for split in ("test", "held_out"):
            test = splits[split]
            preds = _predictions(mesh_net, voxel_net, train, test, protocol, seed,
                                 (train_grids, labels, representatives, grids[split]))
            scores = score_predictions(preds, test, test_grids=grids[split], threshold=threshold, progress=progress)
            part += table_rows(scores, test, split=split)
            if split == "test":
                novelty = novelty_rows(scores)
        t_score = time.perf_counter() - t1 - t_mesh - t_voxel
        for r in part:
            r.update(part="table", protocol=protocol, seconds_mesh=t_mesh, seconds_voxel=t_voxel,
                     seconds_score=t_score)
        _print_table(part, f"\ninputs: {'view 0 of every shape' if protocol == 'first' else 'any view'} "
                           f"({protocol}); time: mesh network {t_mesh:.0f} s, voxel network {t_voxel:.0f} s, "
                           f"scoring {t_score:.0f} s")
        _print_novelty(novelty)
        rows += part + [dict(r, part="novelty", protocol=protocol) for r in novelty]
        if protocol == ("all" if "all" in protocols else protocols[0]):
            if save:
                mean = next(r for r in part if r["split"] == "test" and r["family"] == "mean")
                save_reconstructor(mesh_net, save, f"python -m course bench learn --parts table (n_train={n_train}, "
                                   f"views={views}, steps={steps}, batch={batch}, lr={lr:g}, seed={seed}, inputs "
                                   f"{protocol}); test voxel IoU {mean['iou_mesh']:.3f}")
            if save_voxel and voxel_net is not None:
                mean = next(r for r in part if r["split"] == "test" and r["family"] == "mean")
                save_voxel_reconstructor(voxel_net, save_voxel, f"python -m course bench learn --parts table "
                                         f"(n_train={n_train}, views={views}, steps={steps}, batch={batch}, lr={lr:g}, "
                                         f"seed={seed}, inputs {protocol}); test voxel IoU {mean['iou_voxel']:.3f}")
    return rows


def bench_diversity(ns=(12, 25, 50, 100), n_test=20, views=24, steps=800, batch=16, lr=2e-3, seed=0, clusters=30,
                    threshold=0.05, progress=True) -> list:
    """The mesh network (inputs from any view) against the lookups as the training set grows: one ``bench_table``
    run per number of training shapes per family, without the voxel network; prints one line per run."""
    rows = []
    for n in ns:
        part = bench_table(n, n_test, views, steps, batch, lr, seed, ("all",), min(clusters, 6 * n), False,
                           threshold, progress=progress)
        for r in part:
            r.update(part="diversity" if r["part"] == "table" else "diversity novelty", n_train=n)
        rows += part
    print("\ndiversity: mean voxel IoU as the training set grows (inputs from any view); retrieval and the oracle also "
          "as their difference from the mesh network +- standard error")
    print(f"{'n/family':>8} | {'mesh':>6} {'retrieval':>19} {'oracle':>19} | {'torus: mesh':>11} {'retrieval':>19}")
    for n in ns:
        r = next(q for q in rows if q["n_train"] == n and q.get("split") == "test" and q["family"] == "mean")
        t = next(q for q in rows if q["n_train"] == n and q.get("split") == "held_out" and q["family"] != "mean")
        print(f"{n:>8} | {r['iou_mesh']:6.3f} " + " ".join(
            f"{r[f'iou_{m}']:6.3f} {r[f'iou_{m}_diff']:+.3f}±{r[f'iou_{m}_se']:.3f}" for m in ("retrieval", "oracle"))
            + f" | {t['iou_mesh']:11.3f} {t['iou_retrieval']:6.3f} {t['iou_retrieval_diff']:+.3f}±"
              f"{t['iou_retrieval_se']:.3f}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--parts", choices=("all", "table", "mvtn", "diversity"), default="all",
                        help="which benchmark to run (default all: Table 1 under both input protocols, with the "
                             "test shapes by their nearest training twin, then MVTN's four view modes on rotated "
                             "shapes; about 15 minutes on 2 cores; diversity: the mesh network against the lookups "
                             "as the training set shrinks, about 2 minutes a size)")
    parser.add_argument("--protocols", nargs="+", choices=("first", "all"), default=["first", "all"],
                        help="table: input images from view 0 of every shape (first) or any view (all)")
    parser.add_argument("--no-voxels", action="store_true", help="table: leave the voxel network out")
    parser.add_argument("--clusters", type=int, default=30, help="table: k of the clustering baseline")
    parser.add_argument("--fscore", type=float, default=0.05, help="table: the F-score's distance threshold (world "
                                                                   "units: the shapes fit in [-1, 1]^3)")
    parser.add_argument("--diversity-n", nargs="+", type=int, default=[12, 25, 50, 100],
                        help="diversity: training shapes per family, one run each (inputs from any view)")
    parser.add_argument("--n-train", type=int, default=100, help="table: training shapes per family")
    parser.add_argument("--n-test", type=int, default=20, help="table: test shapes per family")
    parser.add_argument("--views", type=int, default=24, help="table: rendered views per shape (Kato et al.'s 24)")
    parser.add_argument("--steps", type=int, default=800, help="table: training steps of each network")
    parser.add_argument("--batch", type=int, default=16, help="table: shapes per step")
    parser.add_argument("--lr", type=float, default=2e-3, help="table: Adam's initial learning rate")
    parser.add_argument("--seed", type=int, default=0, help="table: data, weights and order")
    parser.add_argument("--save", default="", help="table: write the mesh network trained on inputs from any view "
                                                   "here ('' for nowhere)")
    parser.add_argument("--save-voxel", default="", help="table: write the voxel network trained on inputs from any "
                                                         "view here ('' for nowhere)")
    parser.add_argument("--mvtn-train", type=int, default=40, help="MVTN: training shapes per family")
    parser.add_argument("--mvtn-test", type=int, default=20, help="MVTN: test shapes per family")
    parser.add_argument("--mvtn-views", type=int, default=4, help="MVTN: views per shape")
    parser.add_argument("--mvtn-steps", type=int, default=100, help="MVTN: training steps")
    parser.add_argument("--mvtn-batch", type=int, default=16, help="MVTN: shapes per step")
    parser.add_argument("--mvtn-seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4], help="MVTN: seeds (weights)")
    parser.add_argument("--mvtn-modes", nargs="+", choices=MODES, default=list(MODES),
                        help="MVTN: how the views are chosen (fixed circle, fixed sphere, one learned set, "
                             "predicted per object)")
    parser.add_argument("--mvtn-rotated", nargs="+", choices=("upright", "rotated"), default=["rotated"],
                        help="MVTN: each shape turned by its own random rotation (default), upright, or both")
    parser.add_argument("--plot", default="", help="MVTN: draw the view directions on a sphere in this file")
    parser.add_argument("--quick", action="store_true", help="a tiny run of everything (seconds): a smoke test")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args) -> list[dict]:
    if getattr(args, "quick", False):
        for key, value in QUICK.items():
            setattr(args, key, value)
    progress = not getattr(args, "no_progress", False)
    rows = []
    if args.parts in ("all", "table"):
        rows += bench_table(args.n_train, args.n_test, args.views, args.steps, args.batch, args.lr, args.seed,
                            tuple(args.protocols), args.clusters, not args.no_voxels, args.fscore, args.save or None,
                            args.save_voxel or None, progress)
    if args.parts == "diversity":
        rows += bench_diversity(tuple(args.diversity_n), args.n_test, args.views, args.steps, args.batch, args.lr,
                                args.seed, args.clusters, args.fscore, progress)
    if args.parts in ("all", "mvtn"):
        rows += bench_mvtn(args.mvtn_train, args.mvtn_test, args.mvtn_views, args.mvtn_steps, args.mvtn_seeds,
                           args.mvtn_modes, progress, getattr(args, "plot", "") or None,
                           tuple(r == "rotated" for r in args.mvtn_rotated), args.mvtn_batch)
    return rows
