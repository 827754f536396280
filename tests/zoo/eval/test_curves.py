"""`zoo curves`: CSVLogger metrics read back per metric and drawn."""

from __future__ import annotations

import numpy as np

from zoo.cli import main
from zoo.eval.curves import read_metrics

CSV = """epoch,step,train/loss,train/acc,val/loss,val/acc
0,9,2.0,0.1,,
0,19,1.5,0.3,,
0,19,,,1.7,0.25
1,29,1.0,0.6,,
"""


def test_read_metrics_skips_blanks(tmp_path):
    path = tmp_path / "metrics.csv"
    path.write_text(CSV)
    metrics = read_metrics(path)
    assert sorted(metrics) == ["train/acc", "train/loss", "val/acc", "val/loss"]
    steps, values = metrics["train/loss"]
    np.testing.assert_array_equal(steps, [9, 19, 29])
    np.testing.assert_array_equal(values, [2.0, 1.5, 1.0])
    np.testing.assert_array_equal(metrics["val/loss"][0], [19])


def test_curves_command_writes_png_and_names_missing_csv(tmp_path, capsys):
    run = tmp_path / "run"
    (run / "csv" / "version_0").mkdir(parents=True)
    (run / "csv" / "version_0" / "metrics.csv").write_text(CSV)
    assert main(["curves", str(run)]) == 0
    assert (run / "curves.png").read_bytes()[:4] == b"\x89PNG"
    assert "train/loss" in capsys.readouterr().out
    assert main(["curves", str(tmp_path / "empty")]) == 2
    assert "no metrics.csv under" in capsys.readouterr().out
