"""Every command that plays episodes reads --env, --seed and --max-steps alike (zoo/envs/flags.py):
the same choices, the same refusal of a bad number, and the defaults each command states."""

from __future__ import annotations

import pytest

from zoo.cli import build_parser

# (command, the arguments it needs besides the flag under test)
PLAYING = {
    "eval": ["eval", "--agent", "random", "--env", "craftax"],
    "tables instructions": ["tables", "instructions", "--agent", "scripted", "--out", "o"],
    "play": ["play", "--checkpoint", "weights/cvpt_tiny_cpu", "--out", "o"],
    "data generate": ["data", "generate", "--expert", "random", "--episodes", "1", "--seed", "0",
                      "--out", "o"],
    "demo": ["demo"],
}


def _parse(argv: list[str]):
    return build_parser().parse_args(argv)


@pytest.mark.parametrize("command", sorted(PLAYING))
def test_a_negative_seed_is_refused_alike(command: str, capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        _parse([*PLAYING[command], "--seed", "-1"])
    assert stop.value.code == 2
    assert "argument --seed: expected an integer >= 0, got -1" in capsys.readouterr().err


@pytest.mark.parametrize("command", sorted(PLAYING))
def test_a_zero_step_limit_is_refused_alike(command: str, capsys) -> None:
    with pytest.raises(SystemExit):
        _parse([*PLAYING[command], "--max-steps", "0"])
    assert "argument --max-steps: expected a positive integer, got 0" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["play", "data generate", "demo"])
def test_an_unknown_game_is_refused_alike(command: str, capsys) -> None:
    with pytest.raises(SystemExit):
        _parse([*PLAYING[command], "--env", "minecraft"])
    assert "argument --env: invalid choice: 'minecraft'" in capsys.readouterr().err


def test_each_command_keeps_its_own_defaults() -> None:
    assert (_parse(PLAYING["eval"]).seed, _parse(PLAYING["eval"]).max_steps) == (0, None)
    matrix = _parse(PLAYING["tables instructions"])
    assert (matrix.env, matrix.max_steps, matrix.num_envs) == (["craftax", "crafter"], 200, 20)
    play = _parse(PLAYING["play"])
    assert (play.env, play.seed, play.max_steps) == ("craftax", 0, 500)
    generate = _parse(PLAYING["data generate"])
    assert (generate.env, generate.max_steps, generate.num_envs) == ("craftax", 10_000, 8)


def test_eval_and_generate_need_what_has_no_default(capsys) -> None:
    with pytest.raises(SystemExit):
        _parse(["eval", "--agent", "random"])
    assert "the following arguments are required: --env" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _parse(["data", "generate", "--expert", "random", "--episodes", "1", "--out", "o"])
    assert "the following arguments are required: --seed" in capsys.readouterr().err
