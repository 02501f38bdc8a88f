"""``bench learn`` runs end to end at its ``--quick`` size, prints both tables and writes a loadable checkpoint.
The numbers of a quick run mean nothing; the default run's are the bench's answer."""
import argparse

import torch

from course.bench import learn as bench
from course.learning.reconstruction import load_reconstructor


def _args(*argv):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_the_defaults_are_the_documented_run():
    args = _args()
    assert (args.parts, args.n_train, args.views, args.steps, args.batch, args.mvtn_views) == ("both", 100, 8, 1200,
                                                                                                16, 4)
    assert args.mvtn_modes == ["fixed", "learned"] and bench.REPEAT == 1 and bench.DESCRIPTION


def test_a_quick_run_prints_both_tables_and_saves(tmp_path, capsys):
    path = tmp_path / "net.pt"
    rows = bench.run(_args("--quick", "--no-progress", "--save", str(path), "--plot", str(tmp_path / "views.png")))
    out = capsys.readouterr().out
    assert "IoU net" in out and "held_out  torus" in out and "learned views, seed 0" in out
    recon = [r for r in rows if r.get("split") == "test"]
    assert [r["family"] for r in recon] == ["box", "cylinder", "cone", "capsule", "vase", "star", "mean"]
    assert all(0 <= r["iou_network"] <= 1 and r["chamfer_network"] >= 0 for r in recon)
    mvtn = [r for r in rows if r.get("part") == "mvtn"]
    assert [r["mode"] for r in mvtn] == ["fixed", "learned"] and all(0 <= r["accuracy"] <= 1 for r in mvtn)
    model = load_reconstructor(path)
    assert "n_train=4" in model.note and path.stat().st_size < 600_000 and (tmp_path / "views.png").is_file()
    assert model(torch.zeros(1, 32, 32, 3)).shape == (1, 162, 3)


def test_a_quick_table_prints_every_row_and_saves_both_networks(tmp_path, capsys):
    """Table 1's rows on a tiny set: every method scored with IoU, Chamfer and F-score, paired against the mesh
    network, inputs from any view; both checkpoints load."""
    from course.learning.voxels import load_voxel_reconstructor
    rows = bench.run(_args("--quick", "--no-progress", "--parts", "table", "--n-test", "1", "--save",
                           str(tmp_path / "mesh.pt"), "--save-voxel", str(tmp_path / "voxel.pt")))
    out = capsys.readouterr().out
    assert "inputs: any view (all)" in out and "fscore:" in out and "held_out  torus" in out
    mean = next(r for r in rows if r["split"] == "test" and r["family"] == "mean")
    for method in ("mesh", "voxel", "retrieval", "clustering", "oracle", "sphere"):
        assert 0 <= mean[f"iou_{method}"] <= 1 and 0 <= mean[f"fscore_{method}"] <= 1
        assert mean[f"chamfer_{method}"] >= 0
    assert mean["iou_oracle"] >= mean["iou_retrieval"] and mean["iou_oracle"] >= mean["iou_clustering"]
    assert "iou_voxel_se" in mean and "iou_mesh_diff" not in mean
    assert "inputs all" in load_reconstructor(tmp_path / "mesh.pt").note
    assert "inputs all" in load_voxel_reconstructor(tmp_path / "voxel.pt").note
