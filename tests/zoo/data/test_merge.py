"""Generation as a job array: `zoo data generate --shards A:B` per task, `zoo data merge` after."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zoo.cli import main

GEN = ["data", "generate", "--expert", "random", "--env", "crafter", "--episodes", "6",
       "--episodes-per-shard", "2", "--max-steps", "30", "--seed", "4", "--no-progress"]


def _shas(root: Path) -> dict[str, str]:
    manifest = json.loads((root / "manifest.json").read_text())
    return {e["file"]: e["sha256"] for e in manifest["shards"]}


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("whole")
    assert main([*GEN, "--out", str(out)]) == 0
    return out


def test_ranges_merge_into_the_dataset_a_single_run_writes(whole, tmp_path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert main([*GEN, "--shards", "0:1", "--out", str(a)]) == 0
    assert sorted(_shas(a)) == ["crafterplay-000000.tar"]
    assert main([*GEN, "--shards", "1:", "--out", str(b)]) == 0
    assert main(["data", "merge", str(a), str(b), "--out", str(tmp_path / "all")]) == 0
    assert _shas(tmp_path / "all") == _shas(whole)  # same bytes as one run
    assert main(["data", "info", str(tmp_path / "all")]) == 0


def test_merge_refuses_overlaps_and_other_settings(tmp_path, capsys) -> None:
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    assert main([*GEN, "--shards", "0:2", "--out", str(a)]) == 0
    assert main([*GEN, "--shards", "1:3", "--out", str(b)]) == 0
    assert main(["data", "merge", str(a), str(b), "--out", str(tmp_path / "m")]) == 2
    assert "shard 1 is in both" in capsys.readouterr().err
    other = [*GEN[:-2], "5", "--no-progress"]  # another seed
    assert main([*other, "--shards", "2:3", "--out", str(c)]) == 0
    assert main(["data", "merge", str(a), str(c), "--out", str(tmp_path / "m2")]) == 2
    assert "seed: 4" in capsys.readouterr().err


def test_merge_names_missing_shards_and_a_bad_range_is_an_error(tmp_path, capsys) -> None:
    a = tmp_path / "a"
    assert main([*GEN, "--shards", "0:1", "--out", str(a)]) == 0
    assert main(["data", "merge", str(a), "--out", str(tmp_path / "m")]) == 1
    assert "shards [1, 2] are in no folder yet" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*GEN, "--shards", "7:9", "--out", str(tmp_path / "x")])
    assert "holds none of the dataset's shards 0:3" in capsys.readouterr().err


def test_merge_refuses_a_shard_that_fails_its_checksum(tmp_path, capsys) -> None:
    """A job's shard damaged after it was written (a flipped byte): merging its folder is
    refused, naming the shard, and nothing is merged."""
    job = tmp_path / "job"
    assert main([*GEN, "--shards", "2:", "--out", str(job)]) == 0
    shard = job / "crafterplay-000002.tar"
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))
    capsys.readouterr()
    assert main(["data", "merge", str(job), "--out", str(tmp_path / "m")]) == 2
    assert f"{shard}: sha256 differs from its manifest" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
