"""`zoo data generate|info` in-process: output, checksum failures, argument errors."""

from __future__ import annotations

import json
import shutil

import pytest

from zoo.cli import main

GENERATE = [
    "data", "generate", "--expert", "random", "--episodes", "3", "--seed", "5", "--env", "crafter",
    "--episodes-per-shard", "2", "--chunk-length", "16", "--max-steps", "30", "--num-envs", "2",
    "--no-progress",
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli") / "play"
    assert main([*GENERATE, "--out", str(root)]) == 0
    return root


def test_info_reports_counts_and_rates(dataset, capsys):
    assert main(["data", "info", str(dataset), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["shards"], info["episodes"], info["skipped_shards"]) == (2, 3, 0)
    assert info["steps"] + info["episodes"] == info["frames"]  # + each final observation
    assert info["frames"] <= 3 * 31
    assert 0 <= info["noop_ratio_after"] <= info["noop_ratio_before"] <= 1
    assert len(info["achievement_unlock_rates"]) == 22
    assert 0 < info["frame_bytes_per_frame"] < info["bytes_per_frame"]
    assert main(["data", "info", str(dataset)]) == 0
    text = capsys.readouterr().out
    assert "episodes 3" in text and "noop ratio" in text and "checksums: ok" in text


def test_info_fails_on_checksum_mismatch_and_skips_on_request(dataset, tmp_path, capsys):
    root = tmp_path / "copy"
    shutil.copytree(dataset, root)
    shard = root / "crafterplay-000001.tar"
    data = bytearray(shard.read_bytes())
    data[700] ^= 0xFF
    shard.write_bytes(bytes(data))
    assert main(["data", "info", str(root)]) == 1
    err = capsys.readouterr().err
    assert "checksum failed" in err and "crafterplay-000001.tar" in err
    assert main(["data", "info", str(root), "--skip-corrupt", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["shards"], info["episodes"], info["skipped_shards"]) == (1, 2, 1)
    assert info["bad_shards"][0]["file"].endswith("crafterplay-000001.tar")


def test_rerun_with_other_arguments_is_refused(dataset, capsys):
    args = [*GENERATE, "--out", str(dataset)]
    args[args.index("--seed") + 1] = "6"
    assert main(args) == 2
    assert "seed: 5 there vs 6 now" in capsys.readouterr().err


def test_rerun_of_finished_dataset_does_nothing(dataset, capsys):
    before = (dataset / "manifest.json").read_text()
    assert main([*GENERATE, "--out", str(dataset)]) == 0
    assert (dataset / "manifest.json").read_text() == before


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("--episodes", "0"), "--episodes: expected a positive integer, got 0"),
        (("--expert", "wizard"), "--expert: invalid choice: 'wizard'"),
        (("--chunk-length", "x"), "--chunk-length: expected a positive integer, got 'x'"),
        (("--expert", "ppo"), "--expert ppo needs --checkpoint PATH"),
        (("--out", "FILE"), "exists and is not a folder"),
    ],
)
def test_bad_arguments_give_clear_errors(tmp_path, capsys, change, message):
    afile = tmp_path / "afile"
    afile.write_text("x")
    args = [*GENERATE, "--out", str(tmp_path / "new")]
    flag, value = change
    args[args.index(flag) + 1] = str(afile) if value == "FILE" else value
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_info_on_a_folder_without_manifest(tmp_path, capsys):
    assert main(["data", "info", str(tmp_path)]) == 2
    assert "manifest.json not found" in capsys.readouterr().err


def test_expert_options_reach_the_expert_and_the_manifest(tmp_path, capsys):
    args = [*GENERATE, "--out", str(tmp_path / "play"), "--expert-option", "plants_first=true",
            "--expert-option", "near=6"]
    args[args.index("--expert") + 1] = "scripted"
    assert main(args) == 0
    manifest = json.loads((tmp_path / "play" / "manifest.json").read_text())
    assert manifest["config"]["expert_options"] == {"plants_first": True, "near": 6}
    args[-1] = "near=7"  # resuming with other options is refused like any other argument
    assert main(args) == 2
    assert "expert_options" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--expert-option", "plants_first=maybe"], "plants_first takes true or false, got 'maybe'"),
        (["--expert-option", "near=far"], "near takes int values, got 'far'"),
        (["--expert-option", "no_such_knob=1"], "expected KEY=VALUE with KEY one of"),
        (["--expert-option", "plants_first"], "expected KEY=VALUE"),
    ],
)
def test_bad_expert_options_give_clear_errors(tmp_path, capsys, extra, message):
    with pytest.raises(SystemExit) as exit_info:
        main([*GENERATE, "--out", str(tmp_path / "new"), *extra])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("mine_cost=12", "near_zombie_cost is 16: the planner's step costs must stay <= 15"),
        ("bridge_cost=0", "mine_cost and bridge_cost must be >= 1"),
    ],
)
def test_path_costs_the_planner_cannot_take_are_refused_before_playing(
    tmp_path, capsys, option, message
):
    out = tmp_path / "new"
    with pytest.raises(SystemExit) as exit_info:
        main(["data", "generate", "--expert", "scripted", "--episodes", "1", "--seed", "0",
              "--out", str(out), "--expert-option", option])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_expert_options_need_the_scripted_expert(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main([*GENERATE, "--out", str(tmp_path / "new"), "--expert-option", "plants_first=true"])
    assert "--expert-option applies to --expert scripted, not random" in capsys.readouterr().err
