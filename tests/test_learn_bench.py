"""``bench learn`` runs end to end at its ``--quick`` size, prints every table and writes loadable checkpoints.
The numbers of a quick run mean nothing; the default run's are the bench's answer (README, lecture 13)."""
import argparse

import torch

from course.bench import learn as bench
from course.learning.mvtn import MODES
from course.learning.reconstruction import load_reconstructor
from course.learning.voxels import load_voxel_reconstructor


def _args(*argv):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_the_defaults_are_the_documented_run():
    """The README and lecture 13 quote the default run: both input protocols, 24 views, 800 steps of 16, MVTN's four
    modes over five seeds on rotated shapes."""
    args = _args()
    assert (args.parts, args.n_train, args.n_test, args.views, args.steps, args.batch) == ("all", 100, 20, 24, 800, 16)
    assert args.protocols == ["first", "all"] and args.clusters == 30 and args.fscore == 0.05
    assert args.mvtn_modes == list(MODES) == ["fixed", "sphere", "learned", "predicted"]
    assert (args.mvtn_steps, args.mvtn_batch, args.mvtn_seeds, args.mvtn_rotated) == (100, 16, [0, 1, 2, 3, 4],
                                                                                       ["rotated"])
    assert bench.REPEAT == 1 and bench.DESCRIPTION


def test_a_quick_run_prints_every_table_and_saves_both_networks(tmp_path, capsys):
    """Table 1's rows on a tiny set: every method scored with IoU, Chamfer and F-score, paired against the mesh
    network, inputs from any view; the test shapes by their nearest twin; MVTN's four modes over two seeds; both
    checkpoints load and hold the recipe."""
    rows = bench.run(_args("--quick", "--no-progress", "--n-test", "1", "--save", str(tmp_path / "mesh.pt"),
                           "--save-voxel", str(tmp_path / "voxel.pt"), "--plot", str(tmp_path / "views.png")))
    out = capsys.readouterr().out
    assert "inputs: any view (all)" in out and "fscore:" in out and "held_out  torus" in out
    assert "nearest training twin" in out and "predicted views, seed 1" in out
    table = [r for r in rows if r["part"] == "table"]
    assert [r["family"] for r in table if r["split"] == "test"] == ["box", "cylinder", "cone", "capsule", "vase",
                                                                     "star", "mean"]
    mean = next(r for r in table if r["split"] == "test" and r["family"] == "mean")
    for method in ("mesh", "voxel", "retrieval", "clustering", "oracle", "sphere"):
        assert 0 <= mean[f"iou_{method}"] <= 1 and 0 <= mean[f"fscore_{method}"] <= 1
        assert mean[f"chamfer_{method}"] >= 0
    assert mean["iou_oracle"] >= mean["iou_retrieval"] and mean["iou_oracle"] >= mean["iou_clustering"]
    assert "iou_voxel_se" in mean and "iou_mesh_diff" not in mean
    novelty = [r for r in rows if r["part"] == "novelty"]
    assert sum(r["n"] for r in novelty) == mean["n"]
    assert all(a["oracle_high"] <= b["oracle_low"] for a, b in zip(novelty, novelty[1:]))
    mvtn = [r for r in rows if r["part"] == "mvtn"]
    assert [(r["mode"], r["seed"], r["rotated"]) for r in mvtn] == [(m, s, True) for m in MODES for s in (0, 1)]
    assert all(0 <= r["accuracy"] <= 1 for r in mvtn) and (tmp_path / "views.png").is_file()
    mesh, voxel = load_reconstructor(tmp_path / "mesh.pt"), load_voxel_reconstructor(tmp_path / "voxel.pt")
    assert "inputs all" in mesh.note and "inputs all" in voxel.note and "n_train=4" in mesh.note
    assert (tmp_path / "mesh.pt").stat().st_size < 600_000
    assert mesh(torch.zeros(1, 32, 32, 3)).shape == (1, 162, 3)
    assert voxel(torch.zeros(1, 32, 32, 3)).shape == (1, 32, 32, 32)


def test_the_diversity_axis_prints_a_line_per_size(capsys):
    rows = bench.run(_args("--quick", "--no-progress", "--parts", "diversity", "--n-test", "1", "--no-voxels"))
    out = capsys.readouterr().out
    assert "diversity:" in out
    means = [r for r in rows if r["part"] == "diversity" and r["split"] == "test" and r["family"] == "mean"]
    assert [r["n_train"] for r in means] == [2, 3] and all("iou_voxel" not in r for r in means)
