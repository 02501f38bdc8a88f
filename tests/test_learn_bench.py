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
