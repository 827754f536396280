"""A bad model file given to a `zoo` command is one line naming the file and what was expected,
never a traceback, and never torch's advice to load with ``weights_only=False``; a free-text
instruction is allowed and named with its nearest caption."""

from __future__ import annotations

import collections
import json
import shutil
import zipfile
from pathlib import Path

import pytest
import torch

from zoo.agents.csteve1_agent import GoalEncoder, instruction_note
from zoo.cli import main
from zoo.files import sha256_file
from zoo.weights import load_model
from zoo.weights.checkpoint_io import CheckpointError, read_torch_file
from zoo.weights.export import CHECKSUM_FILE, CONFIG_FILE, WEIGHTS_FILE

WEIGHTS = Path(__file__).resolve().parents[2] / "weights"
EXPECTED = "expected a `zoo fit` checkpoint (.ckpt) or a `zoo export` folder"


class Pickled:
    """A class a weights-only load refuses to unpickle."""


def _bad_checkpoint(tmp_path: Path, what: str) -> Path:
    path = tmp_path / f"{what}.ckpt"
    if what == "empty":
        path.write_bytes(b"")
    elif what == "garbage":
        path.write_bytes(bytes(range(256)) * 3)
    elif what == "truncated":
        torch.save({"state_dict": {"w": torch.zeros(64)}}, path)
        path.write_bytes(path.read_bytes()[:200])
    elif what == "other_zip":
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("hello.txt", "hi")
    return path


UNREADABLE = {
    "empty": "not a readable checkpoint (empty file)",
    "garbage": "not a readable checkpoint (not a torch zip archive)",
    "truncated": "not a readable checkpoint (truncated or corrupt torch zip archive)",
    "other_zip": "not a readable checkpoint (truncated or corrupt torch zip archive)",
}


@pytest.mark.parametrize("what", sorted(UNREADABLE))
def test_an_unreadable_checkpoint_names_the_file_and_the_problem(tmp_path, what) -> None:
    path = _bad_checkpoint(tmp_path, what)
    with pytest.raises(CheckpointError) as err:
        read_torch_file(path)
    assert str(err.value) == f"{path}: {UNREADABLE[what]}; {EXPECTED}"
    assert err.value.__cause__ is None and err.value.__suppress_context__  # torch's text is gone


def test_export_of_a_folder_that_is_no_export_names_what_it_lacks(tmp_path, capsys) -> None:
    """An export folder is written again (tests/zoo/agents/test_agent_spec.py); any other
    folder is one line naming what an export holds."""
    folder = tmp_path / "empty"
    folder.mkdir()
    assert main(["export", "--checkpoint", str(folder), "--out", str(tmp_path / "x")]) == 2
    assert _one_error_line(capsys, "export") == (
        f"zoo export: error: {folder / 'config.json'} missing: {folder} is not a `zoo export` "
        "folder"
    )


def test_a_pickled_object_is_refused_by_name_without_the_unsafe_advice(tmp_path) -> None:
    path = tmp_path / "pickled.ckpt"
    torch.save({"state_dict": collections.OrderedDict(), "extra": Pickled()}, path)
    with pytest.raises(CheckpointError, match=r"pickled Python object \(\S+\.Pickled\)") as err:
        read_torch_file(path)
    assert "weights_only" not in str(err.value) and str(path) in str(err.value)


def test_a_torch_file_that_is_not_a_dict_is_named(tmp_path) -> None:
    path = tmp_path / "tensor.ckpt"
    torch.save(torch.zeros(2), path)
    with pytest.raises(CheckpointError, match=r"tensor.ckpt: holds a Tensor, not a checkpoint"):
        read_torch_file(path)


def test_a_bad_rl_checkpoint_says_what_was_expected(tmp_path) -> None:
    from zoo.rl.play import load_rl_agent

    path = tmp_path / "update_000001.pt"
    path.write_bytes(b"")
    expected = r"\(empty file\); expected a `zoo rl train` checkpoint"
    with pytest.raises(CheckpointError, match=expected):
        load_rl_agent(path, 1)


def _one_error_line(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and "weights_only" not in err
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"zoo {command}: error: ")
    return err


def _eval(checkpoint: Path, out: Path, *extra: str) -> int:
    return main(["eval", "--checkpoint", str(checkpoint), "--env", "crafter", "--episodes", "1",
                 "--no-gif", "--out", str(out), *extra])


@pytest.mark.parametrize("what", ["empty", "garbage"])
def test_eval_play_and_export_report_a_bad_checkpoint_in_one_line(tmp_path, capsys, what) -> None:
    path = _bad_checkpoint(tmp_path, what)
    assert _eval(path, tmp_path / "eval") == 2
    assert f"{path}: {UNREADABLE[what]}; {EXPECTED}" in _one_error_line(capsys, "eval")

    assert main(["export", "--checkpoint", str(path), "--out", str(tmp_path / "x")]) == 2
    err = _one_error_line(capsys, "export")
    assert f"{path}: {UNREADABLE[what]}; expected a `zoo fit` checkpoint (.ckpt)" in err

    with pytest.raises(SystemExit) as exited:
        main(["play", "--checkpoint", str(path), "--out", str(tmp_path / "play")])
    assert exited.value.code == f"zoo play: error: {path}: {UNREADABLE[what]}; {EXPECTED}"


def _export_folder(tmp_path: Path, without: str | None = None) -> Path:
    folder = tmp_path / "export"
    shutil.copytree(WEIGHTS / "cvpt_tiny_cpu", folder)
    if without is not None:
        (folder / without).unlink()
    return folder


@pytest.mark.parametrize("without", [CHECKSUM_FILE, WEIGHTS_FILE])
@pytest.mark.parametrize("agent", [[], ["--agent", "cvpt"]], ids=["found", "given"])
def test_an_export_folder_missing_a_file_names_it(tmp_path, capsys, without, agent) -> None:
    folder = _export_folder(tmp_path, without)
    assert _eval(folder, tmp_path / "eval", *agent) == 2
    err = _one_error_line(capsys, "eval")
    assert f"{folder / without} missing: {folder} is not a `zoo export` folder" in err


def test_a_malformed_sha256_txt_names_its_line(tmp_path) -> None:
    folder = _export_folder(tmp_path)
    (folder / CHECKSUM_FILE).write_text("not-a-sum-line\n")
    with pytest.raises(CheckpointError, match=rf"{folder / CHECKSUM_FILE} line 1: expected"):
        load_model(folder)


def _write_config(folder: Path, text: str) -> None:
    """Replace config.json and its sum in sha256.txt, so only its content is wrong."""
    config = folder / CONFIG_FILE
    config.write_text(text)
    sums = [f"{sha256_file(config)}  {CONFIG_FILE}" if line.endswith(CONFIG_FILE) else line
            for line in (folder / CHECKSUM_FILE).read_text().splitlines()]
    (folder / CHECKSUM_FILE).write_text("\n".join(sums) + "\n")


def test_a_corrupt_config_json_names_the_file_and_where(tmp_path, capsys) -> None:
    folder = _export_folder(tmp_path)
    lines = (folder / CONFIG_FILE).read_text().splitlines(keepends=True)
    _write_config(folder, "".join([*lines[:2], lines[2].replace(",", ",,"), *lines[3:]]))
    where = r"line 3 column \d+"
    message = rf"{folder / CONFIG_FILE}: not valid JSON \(.*{where}"
    with pytest.raises(CheckpointError, match=message):
        load_model(folder)
    assert _eval(folder, tmp_path / "eval") == 2
    err = _one_error_line(capsys, "eval")
    assert f"{folder / CONFIG_FILE}: not valid JSON" in err and "line 3 column" in err


def test_a_config_json_that_is_not_an_object_is_named(tmp_path) -> None:
    folder = _export_folder(tmp_path)
    _write_config(folder, json.dumps(["cvpt"]))
    with pytest.raises(CheckpointError, match=rf"{folder / CONFIG_FILE}: holds a JSON list"):
        load_model(folder)


@pytest.fixture(scope="module")
def shipped_goals() -> GoalEncoder:
    return GoalEncoder(load_model(WEIGHTS / "cclip_cpu", "cclip"))


def test_a_caption_is_its_own_nearest_caption(shipped_goals) -> None:
    caption, similarity = shipped_goals.nearest_caption("obtain wood")
    assert caption == "obtain wood" and similarity == pytest.approx(1.0, abs=1e-4)
    assert instruction_note(shipped_goals, "obtain wood") is None


@pytest.mark.parametrize("text, caption", [
    ("get some wood", "obtain wood"),
    ("make a wooden pickaxe", "craft wood pickaxe"),
    ("kill the zombie", "kill zombie"),
])
def test_free_text_is_named_with_its_nearest_caption(shipped_goals, text, caption) -> None:
    assert shipped_goals.nearest_caption(text)[0] == caption
    note = instruction_note(shipped_goals, text)
    assert note.startswith(f"instruction {text!r} is free text, not one of the 61 captions; "
                           f"nearest caption {caption!r} (C-CLIP cosine similarity 0.")


STEVE = ["--checkpoint", str(WEIGHTS / "csteve1_cpu"), "--cclip", str(WEIGHTS / "cclip_cpu"),
         "--prior", str(WEIGHTS / "prior_cpu"), "--instruction", "get some wood",
         "--env", "crafter", "--max-steps", "2"]


@pytest.mark.parametrize("command, extra", [
    ("play", []), ("eval", ["--task", "T2", "--episodes", "1", "--no-gif"]),
])
def test_play_and_eval_say_a_free_text_instruction_is_free_text(
    tmp_path, capsys, command, extra
) -> None:
    assert main([command, *STEVE, *extra, "--out", str(tmp_path / "out")]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "note:" in line]
    assert len(notes) == 1 and notes[0].startswith(
        f"zoo {command}: note: instruction 'get some wood' is free text, not one of the 61 "
        "captions; nearest caption 'obtain wood' (C-CLIP cosine similarity 0."
    )
