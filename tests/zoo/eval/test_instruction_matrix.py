"""`zoo tables instructions`: the verdict on hand-made matrices, the Wilson cells, and the command
end to end with the scripted expert (played once, then read back)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zoo.cli import build_parser, main
from zoo.envs.base import episode_seed
from zoo.eval import instruction_matrix as matrix
from zoo.eval.instruction_matrix import COLUMNS, NO_INSTRUCTION

SAPLING, DRINK, TABLE = COLUMNS[0], COLUMNS[1], COLUMNS[2]
# rows x (collect_sapling, collect_drink, place_table), 20 episodes per row
HAND_MADE = {
    "obtain sapling": (18, 7, 0),
    "obtain drink": (10, 7, 16),
    "place table on grass": (3, 1, 2),
    NO_INSTRUCTION: (5, 7, 15),
}
# the command of docs/results/csteve1.md
DOCS_COMMAND = ["tables", "instructions", "--checkpoint", "weights/csteve1_cpu", "--cclip",
                "weights/cclip_cpu", "--prior", "weights/prior_cpu", "--cfg-scale", "0.5",
                "--env", "craftax", "crafter", "--episodes", "50", "--max-steps", "200",
                "--num-envs", "25", "--seed", "5", "--out", "runs/instructions/csteve1_cpu"]


def counts(rows: dict[str, tuple[int, int, int]]) -> matrix.Counts:
    names = ("collect_sapling", "collect_drink", "place_table")
    return {row: dict(zip(names, ks, strict=True)) for row, ks in rows.items()}


def test_the_verdict_on_a_hand_made_matrix() -> None:
    columns = matrix.verdict(counts(HAND_MADE), 20, (SAPLING, DRINK, TABLE))
    sapling, drink, table = columns
    # own 18/20 (69.9-97.2%) tops the column and clears none (5/20, 11.2-46.9%), but its interval
    # overlaps the best other's (10/20, 29.9-70.1%) by 0.2 points
    assert sapling["own_is_max"] and not sapling["own_is_max_tied"]
    assert sapling["separated_from_none"] and not sapling["separated_from_best_other"]
    assert sapling["best_other"] == ["obtain drink"] and sapling["best_other_count"] == 10
    # a three-way tie at 7: the maximum, tied, neither above nor below no instruction
    assert drink["own_is_max"] and drink["own_is_max_tied"]
    assert not (drink["above_none"] or drink["below_none"] or drink["worse_than_none"])
    assert drink["best_other"] == ["obtain sapling"]
    # told 2/20 (2.8-30.1%), untold 15/20 (53.1-88.8%): worse told, disjoint intervals
    assert not table["own_is_max"] and table["below_none"] and table["worse_than_none"]
    assert matrix.summarize(columns) == {
        "columns": 3, "own_is_max": 2, "own_is_max_tied": 1, "above_none": 1,
        "separated_from_none": 1, "below_none": 1, "worse_than_none": 1,
        "separated_from_best_other": 0,
    }
    line = matrix.verdict_line("crafter", matrix.summarize(columns))
    assert line.startswith("crafter: own instruction is the column maximum in 2 of 3 columns")
    assert "above no instruction in 1, disjoint 95% intervals in 1;" in line


def test_disjoint_intervals_are_a_stricter_bar_than_a_two_proportion_test() -> None:
    """50 episodes a row. Told 38 (Wilson 62.6-85.7%) vs untold 27 (40.4-67.0%): the intervals
    overlap, so not separated, yet the two-proportion test gives p = 0.021 (z = 2.306). Told 40
    (67.0-88.8%) vs untold 25 (36.6-63.4%): disjoint, p = 0.00166 (pooled 0.65, z = 0.3 /
    0.0954 = 3.145). Swapped, told below untold: worse than none only when disjoint."""
    def column(told: int, untold: int) -> dict:
        rows = counts({"obtain sapling": (told, 0, 0), NO_INSTRUCTION: (untold, 0, 0)})
        return matrix.verdict(rows, 50, (SAPLING,))[0]

    overlap, disjoint = column(38, 27), column(40, 25)
    assert overlap["above_none"] and not overlap["separated_from_none"]
    assert overlap["p_two_proportion_vs_none"] == pytest.approx(0.021098, abs=1e-6)
    assert disjoint["separated_from_none"]
    assert disjoint["p_two_proportion_vs_none"] == pytest.approx(0.001662, abs=1e-6)
    assert not column(27, 38)["worse_than_none"] and column(25, 40)["worse_than_none"]
    assert matrix.versus_none({"columns": [overlap, disjoint, column(25, 40)]}, 50)[2:] == [
        "| collect_sapling | 38/50 | 27/50 | no | 0.021 |",
        "| collect_sapling | 40/50 | 25/50 | above | 0.002 |",
        "| collect_sapling | 25/50 | 40/50 | below | 0.002 |",
    ]


def test_intervals_that_touch_are_not_separated(monkeypatch: pytest.MonkeyPatch) -> None:
    """No pair of counts gives Wilson bounds that meet exactly, so the cells' intervals are
    set by hand: told 60-80% touches untold 40-60% at 60, a shared point."""
    hand = {30: [60.0, 80.0], 20: [40.0, 60.0]}
    monkeypatch.setattr(matrix, "interval", lambda k, n: hand[k])
    for told, untold in ((30, 20), (20, 30)):
        rows = counts({"obtain sapling": (told, 0, 0), NO_INSTRUCTION: (untold, 0, 0)})
        c = matrix.verdict(rows, 50, (SAPLING,))[0]
        assert not (c["separated_from_none"] or c["worse_than_none"])


def test_one_more_episode_separates_from_the_best_other() -> None:
    rows = {**HAND_MADE, "obtain sapling": (19, 7, 0)}  # 19/20: 76.4-99.1%, above 70.1%
    assert matrix.verdict(counts(rows), 20, (SAPLING,))[0]["separated_from_best_other"]


@pytest.mark.parametrize(
    "k, n, low, high",  # by hand: center (p + z²/2n) / (1 + z²/n) ± z/(1 + z²/n) √(p(1-p)/n + z²/4n²)
    [(0, 20, 0.0, 16.11), (10, 20, 29.93, 70.07), (18, 20, 69.90, 97.21), (20, 20, 83.89, 100.0),
     (1, 2, 9.45, 90.55),
     # 38/50: center 0.798416 / 1.076832 = 0.741449, half 1.96 / 1.076832 √0.00403216 = 0.115578
     (38, 50, 62.59, 85.70), (27, 50, 40.40, 67.03)],
)
def test_cells_carry_wilson_95_intervals(k: int, n: int, low: float, high: float) -> None:
    assert matrix.interval(k, n) == pytest.approx([low, high], abs=0.01)


def test_a_cell_counts_first_unlocks_within_the_horizon() -> None:
    rows = {"obtain sapling": [{"collect_sapling": 200}, {"collect_sapling": 201}, {}],
            NO_INSTRUCTION: [{"collect_sapling": 1, "collect_wood": 3}, {}, {}]}
    assert matrix.count_matrix(rows, (SAPLING,), 200) == {
        "obtain sapling": {"collect_sapling": 1}, NO_INSTRUCTION: {"collect_sapling": 1}}


def test_a_shorter_horizon_scores_the_same_episodes_as_a_shorter_run() -> None:
    # first unlock steps of 3 episodes per row: scored within 10 steps, each row keeps only
    # the unlocks a 10-step run would have seen (an agent's play does not depend on L)
    rows = {
        "obtain sapling": [{"collect_sapling": 4}, {"collect_sapling": 12}, {}],
        "obtain drink": [{"collect_drink": 30, "collect_sapling": 9}, {}, {}],
        "place table on grass": [{"place_table": 10}, {"place_table": 11}, {}],
        NO_INSTRUCTION: [{"collect_sapling": 15, "place_table": 2}, {}, {}],
    }
    columns = (SAPLING, DRINK, TABLE)
    long, short = (matrix.score(rows, columns, 3, h, "crafter") for h in (40, 10))
    assert long["counts"]["obtain sapling"]["collect_sapling"] == 2
    assert short["counts"]["obtain sapling"]["collect_sapling"] == 1
    assert short["counts"][NO_INSTRUCTION] == {"collect_sapling": 0, "collect_drink": 0,
                                               "place_table": 1}
    assert long["counts"]["obtain drink"]["collect_drink"] == 1
    assert short["counts"]["obtain drink"]["collect_drink"] == 0
    # within 40 steps every own instruction leads its column; within 10 all three only tie
    assert long["verdict"]["own_is_max"] == short["verdict"]["own_is_max"] == 3
    assert (long["verdict"]["own_is_max_tied"], short["verdict"]["own_is_max_tied"]) == (0, 3)
    assert matrix.check_horizons([10, 40, 10], 40) == (10,)
    with pytest.raises(ValueError, match="--horizons 50: the rows play 40 steps"):
        matrix.check_horizons([10, 50], 40)


def test_the_default_rows_are_the_task_suites_captions() -> None:
    assert [c.instruction for c in COLUMNS] == [
        "obtain sapling", "obtain drink", "place table on grass", "obtain wood",
        "place plant on grass", "craft wood pickaxe"]
    assert matrix.pick_columns(None) == COLUMNS
    assert matrix.pick_columns(["craft wood pickaxe", "obtain sapling"]) == (COLUMNS[0], COLUMNS[5])
    with pytest.raises(ValueError, match="unknown instruction 'obtain diamond'"):
        matrix.pick_columns(["obtain diamond"])


def test_the_docs_command_parses() -> None:
    args = build_parser().parse_args(DOCS_COMMAND)
    assert args.handler is not None and args.protocol == "instructions"
    assert (args.episodes, args.max_steps, args.num_envs, args.seed) == (50, 200, 25, 5)
    assert args.env == ["craftax", "crafter"] and args.cfg_scale == 0.5
    assert args.checkpoint == Path("weights/csteve1_cpu") and args.instructions is None
    defaults = build_parser().parse_args(["tables", "instructions", "--agent", "scripted",
                                          "--out", "o"])
    assert (defaults.max_steps, defaults.episodes, defaults.cfg_scale) == (200, 100, None)


def test_the_scripted_expert_plays_the_matrix_then_a_rerun_reads_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "matrix"
    argv = ["tables", "instructions", "--agent", "scripted", "--env", "crafter", "--episodes", "2",
            "--num-envs", "2", "--max-steps", "40", "--instructions", "obtain sapling",
            "--horizons", "20", "--out", str(out)]
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["rows"] == ["obtain sapling", NO_INSTRUCTION]
    assert report["setting"]["agent"] == {"kind": "scripted", "temperature": 1.0}
    game = report["games"]["crafter"]
    assert set(game["seconds_played"]) == {"obtain sapling", NO_INSTRUCTION}
    assert game["verdict"]["columns"] == 1 and "crafter: own instruction" in game["verdict_line"]
    for name in ("obtain_sapling", "no_instruction"):  # both rows play the same worlds
        row = json.loads((out / "crafter" / f"{name}.json").read_text())
        assert [e["seed"] for e in row["episodes"]] == [episode_seed(0, j) for j in range(2)]
    assert game["verdict_line"] in (out / "report.md").read_text()
    assert "| column | told | untold | disjoint 95% intervals | two-proportion p |" in (
        out / "report.md").read_text()
    within = game["horizons"]["20"]  # the same saved rows, scored within 20 steps
    rows = {name: [json.loads((out / "crafter" / f"{name}.json").read_text())]
            for name in ("obtain_sapling", "no_instruction")}
    for label, name in (("obtain sapling", "obtain_sapling"), (NO_INSTRUCTION, "no_instruction")):
        steps = [e["unlock_step"].get("collect_sapling", 0) for e in rows[name][0]["episodes"]]
        assert within["counts"][label]["collect_sapling"] == sum(1 <= s <= 20 for s in steps)
    assert "### crafter, the same episodes within 20 steps" in (out / "report.md").read_text()
    assert (out / "matrix.png").read_bytes().startswith(b"\x89PNG")

    def no_play(*args, **kwargs):
        raise AssertionError("a saved row was played again")

    monkeypatch.setattr(matrix, "evaluate", no_play)
    capsys.readouterr()
    assert main(argv) == 0
    assert "read from" in capsys.readouterr().out
    again = json.loads((out / "report.json").read_text())
    assert again["games"]["crafter"]["counts"] == game["counts"]
    assert again["games"]["crafter"]["seconds_played"] == {}
    # another seed would mix worlds: refused before anything plays
    assert main([*argv[:-2], "--seed", "1", "--out", str(out)]) == 2
    assert "was played with another setting {'seed': 0}" in capsys.readouterr().err


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--agent", "scripted", "--instructions", "obtain diamond"],
         "unknown instruction 'obtain diamond'"),
        (["--agent", "random"], "agent 'random' does not follow instructions"),
        (["--agent", "scripted", "--cfg-scale", "1"], "apply to C-Steve-1 only"),
        ([], "give --agent NAME (one of random, scripted"),
        (["--checkpoint", "weights/csteve1_cpu", "--cclip", "weights/cclip_cpu"],
         "give --cclip and --prior together"),
        (["--checkpoint", "nope"], "--checkpoint nope does not exist"),
        (["--agent", "scripted", "--max-steps", "50", "--horizons", "60"],
         "--horizons 60: the rows play 50 steps"),
    ],
)
def test_bad_input_is_a_one_line_error(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["tables", "instructions", *flags, "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("zoo tables instructions: error: ") and err.count("\n") == 1
    assert message in err
    assert not (tmp_path / "m").exists()
