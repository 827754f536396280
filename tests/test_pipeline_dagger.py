"""`zoo pipeline` with a `kind: dagger` config: the config is read strictly, the plan wires each
round to the last one's checkpoint, and the pipeline's hash-based skipping reruns exactly the
rounds a new checkpoint feeds. A fake `zoo` writes what each command would, so nothing trains.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
from pathlib import Path

import pytest
import torch
import yaml

from zoo.cli import build_parser, main
from zoo.pipeline.checks import Missing
from zoo.pipeline.config import DaggerPipelineConfig, load_pipeline_config
from zoo.pipeline.dagger import dagger_plan
from zoo.pipeline.report import write_reports
from zoo.pipeline.runner import run_stages
from zoo.pipeline.stages import Stage

REPO = Path(__file__).resolve().parents[1]
VALUES = {
    "kind": "dagger", "expert_data": "EXPERT", "initial_learner": "R0.ckpt",
    "fit_config": str(REPO / "configs/cvpt_tiny_cpu_dagger.yaml"),
    "fit_args": "--trainer.max_steps=2", "rounds": [0.3, 0.1], "mix": "step", "env": "craftax",
    "episodes": 4, "seed": 100, "max_steps": 50, "episodes_per_shard": 2, "num_envs": 2,
    "workers": 1, "expert_weight": 3.0, "round_weight": 1.0, "eval_episodes": 3,
    "eval_num_envs": 3, "eval_games": ["craftax", "crafter"],
}
NAMES = ["dagger-r1", "fit-r1", "eval-r1-craftax", "eval-r1-crafter",
         "dagger-r2", "fit-r2", "eval-r2-craftax", "eval-r2-crafter"]


def _config(tmp_path: Path, **change) -> DaggerPipelineConfig:
    """VALUES with the expert data and the initial learner under ``tmp_path``."""
    values = {k: v for k, v in VALUES.items() if k != "kind"}
    values.update(expert_data=str(tmp_path / "expert"), initial_learner=str(tmp_path / "r0.ckpt"))
    values.update(change)
    values.update(rounds=tuple(values["rounds"]), eval_games=tuple(values["eval_games"]))
    return DaggerPipelineConfig(**values)


def _option(argv: list[str], name: str) -> str:
    """The value of ``--name V`` or ``--name=V`` in ``argv``."""
    for i, arg in enumerate(argv):
        if arg == name:
            return argv[i + 1]
        if arg.startswith(name + "="):
            return arg.split("=", 1)[1]
    raise KeyError(name)


# --- the config ------------------------------------------------------------------------------

def test_shipped_dagger_config_loads():
    config = load_pipeline_config(REPO / "configs/pipeline_dagger.yaml")
    assert isinstance(config, DaggerPipelineConfig)
    assert config.rounds == (0.3, 0.1) and config.eval_games == ("craftax", "crafter")
    assert config.seed == 100 and config.mix == "step" and Path(REPO / config.fit_config).is_file()


@pytest.mark.parametrize(("change", "words"), [
    ({"betaz": [0.3]}, ["unknown key(s) ['betaz']", "DaggerPipelineConfig fields are"]),
    ({"rounds": None}, ["missing key(s) ['rounds']"]),
    ({"eval_num_envs": None}, ["missing key(s) ['eval_num_envs']"]),
    ({"rounds": 0.3}, ["rounds must be a list of float"]),
    ({"rounds": [0.3, "lots"]}, ["rounds[1] must be float", "lots"]),
    ({"rounds": [1.5]}, ["every beta must be in [0, 1]", "1.5"]),
    ({"rounds": []}, ["rounds must list at least one beta"]),
    ({"eval_games": ["minecraft"]}, ["eval_games must be in", "minecraft"]),
    ({"mix": "sometimes"}, ["mix must be one of", "sometimes"]),
    ({"fit_config": "configs/nope.yaml"}, ["fit_config: configs/nope.yaml is not a file"]),
    ({"kind": "dagerr"}, ["kind must be one of ['dagger']", "dagerr"]),
])
def test_bad_dagger_config_is_one_line(tmp_path, capsys, change, words):
    values = {**VALUES, **change}
    values = {k: v for k, v in values.items() if v is not None or k not in ("rounds",
                                                                            "eval_num_envs")}
    config = tmp_path / "bad.yaml"
    config.write_text(yaml.safe_dump(values))
    assert main(["pipeline", "--config", str(config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"zoo pipeline: {config}") and "\n" not in err, err
    assert all(word in err for word in words), err
    assert not (tmp_path / "out").exists()


def test_help_names_the_dagger_config(capsys):
    with pytest.raises(SystemExit):
        main(["pipeline", "--help"])
    text = capsys.readouterr().out
    assert "kind: dagger" in text and "configs/pipeline_dagger.yaml" in text


# --- the plan ----------------------------------------------------------------------------------

def test_two_rounds_wire_each_round_to_the_last(tmp_path):
    config, out = _config(tmp_path), tmp_path / "out"
    stages = {s.name: s for s in dagger_plan(config, out)}
    assert list(stages) == NAMES
    assert {name: s.needs for name, s in stages.items()} == {
        "dagger-r1": (), "fit-r1": ("dagger-r1",),
        "eval-r1-craftax": ("fit-r1",), "eval-r1-crafter": ("fit-r1",),
        "dagger-r2": ("fit-r1",), "fit-r2": ("fit-r1", "dagger-r1", "dagger-r2"),
        "eval-r2-craftax": ("fit-r2",), "eval-r2-crafter": ("fit-r2",),
    }
    learner, expert = tmp_path / "r0.ckpt", tmp_path / "expert" / "manifest.json"
    assert stages["dagger-r1"].reads == (learner,) and stages["dagger-r2"].reads == ()
    assert stages["fit-r1"].reads == (learner, expert) and stages["fit-r2"].reads == (expert,)
    assert stages["dagger-r1"].resumable and not stages["fit-r1"].resumable

    keys = {"fit-r1": Path("R1.ckpt"), "fit-r2": Path("R2.ckpt")}
    argv = {name: s.command(keys) for name, s in stages.items()}
    assert argv["dagger-r1"] == [
        "data", "dagger", "--checkpoint", str(learner), "--round", "1", "--beta", "0.3",
        "--mix", "step", "--episodes", "4", "--seed", "101", "--max-steps", "50",
        "--env", "craftax", "--episodes-per-shard", "2", "--num-envs", "2", "--workers", "1",
        "--out", str(out / "data/r1"), "--no-progress"]
    assert argv["dagger-r2"][:8] == ["data", "dagger", "--checkpoint", "R1.ckpt",
                                     "--round", "2", "--beta", "0.1"]
    assert _option(argv["dagger-r2"], "--seed") == "102"
    for r, init in ((1, str(learner)), (2, "R1.ckpt")):
        fit = argv[f"fit-r{r}"]
        assert fit[:3] == ["fit", f"--config={config.fit_config}", "--trainer.max_steps=2"]
        assert _option(fit, "--trainer.default_root_dir") == str(out / f"runs/fit-r{r}")
        assert _option(fit, "--model.init_args.init_weights") == init
    sources = json.loads(_option(argv["fit-r2"], "--data.init_args.sources"))
    assert sources == [{"root": str(tmp_path / "expert"), "weight": 3.0},
                       {"root": str(out / "data/r1"), "weight": 1.0},
                       {"root": str(out / "data/r2"), "weight": 1.0}]
    assert len(json.loads(_option(argv["fit-r1"], "--data.init_args.sources"))) == 2
    assert argv["eval-r2-crafter"] == [
        "eval", "--checkpoint", "R2.ckpt", "--env", "crafter", "--episodes", "3",
        "--num-envs", "3", "--no-gif", "--out", str(out / "eval/r2-crafter")]


def test_the_planned_commands_parse(tmp_path, capsys):
    """argparse takes the data and eval commands; LightningCLI reads the fit command's sources
    (JSON, any path) and weights as planned (printing the config reads no data or weights)."""
    from lit_models.cli import run_lightning_cli

    keys = {"fit-r1": Path("R1.ckpt"), "fit-r2": Path("R2.ckpt")}
    config = _config(tmp_path, expert_data=str(tmp_path / "expert data: 3, [early]"))
    for stage in dagger_plan(config, tmp_path / "out"):
        argv = stage.command(keys)
        if argv[0] != "fit":
            assert callable(build_parser().parse_args(argv).handler)
            continue
        printed = io.StringIO()
        with pytest.raises(SystemExit) as exit_info, contextlib.redirect_stdout(printed):
            run_lightning_cli([*argv, "--print_config"])
        assert exit_info.value.code in (0, None), capsys.readouterr().err
        parsed = yaml.safe_load(printed.getvalue())
        assert parsed["data"]["init_args"]["sources"] == json.loads(
            _option(argv, "--data.init_args.sources"))
        assert parsed["data"]["init_args"]["sources"][0]["root"] == config.expert_data
        assert parsed["model"]["init_args"]["init_weights"] == _option(
            argv, "--model.init_args.init_weights")
        assert parsed["trainer"]["max_steps"] == 2


# --- skipping and rerunning, with a fake `zoo` ---------------------------------------------------

class FakeZoo:
    """Writes what each command would: a rollout manifest, a run's last.ckpt, an eval report.
    Every file's bytes depend on the files its command reads; every fit's bytes are new (a
    retrained round is a new checkpoint)."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.fits = 0

    def __call__(self, argv: list[str]) -> str | None:
        verb = argv[1] if argv[0] == "data" else argv[0]
        self.calls.append(verb)
        if verb == "dagger":
            out = Path(_option(argv, "--out"))
            out.mkdir(parents=True)
            learner = Path(_option(argv, "--checkpoint")).read_bytes().hex()
            dagger = {"mix": "step", "beta": float(_option(argv, "--beta")), "learner": learner}
            manifest = {"config": {"expert": "scripted", "env": "craftax", "dagger": dagger},
                        "shards": [{"episodes": 2, "steps": 40, "bytes": 1000,
                                    "dagger": {"learner_agreement": 0.25, "expert_share": 0.3}}]}
            (out / "manifest.json").write_text(json.dumps(manifest))
        elif verb == "fit":
            self.fits += 1
            run = Path(_option(argv, "--trainer.default_root_dir")) / "run" / "checkpoints"
            run.mkdir(parents=True)
            state = {"monitor": "val/loss", "best_model_score": torch.tensor(0.5)}
            torch.save({"global_step": 2, "callbacks": {"ModelCheckpoint": state},
                        "fit": torch.tensor(self.fits)}, run / "last.ckpt")
        else:
            out = Path(_option(argv, "--out"))
            out.mkdir(parents=True)
            stat = {"mean": 1.5, "std": 0.5}
            report = {"env": _option(argv, "--env"), "episodes": 3, "crafter_score": stat,
                      "normalized_return": stat, "episode_length": {"mean": 120},
                      "episode_end_percent": {"survived": 0}}
            (out / "report.json").write_text(json.dumps(report))
        return None


def _one_file(output: Path) -> Path:
    """The check of rollouts and training, for the fake's files: the one file written."""
    files = [p for p in output.rglob("*") if p.is_file()] if output.exists() else []
    if not files:
        raise Missing(f"{output} holds nothing yet")
    (key,) = files
    return key


def _stages(config: DaggerPipelineConfig, out: Path) -> list[Stage]:
    """The plan, its rollout and training checks swapped for the fake's (evals keep theirs)."""
    return [s if s.name.startswith("eval-") else dataclasses.replace(s, check=_one_file)
            for s in dagger_plan(config, out)]


def _statuses(doc: dict) -> dict[str, str]:
    return {r["name"]: r["status"] for r in doc["stages"]}


@pytest.fixture
def inputs(tmp_path: Path) -> DaggerPipelineConfig:
    (tmp_path / "expert").mkdir()
    (tmp_path / "expert" / "manifest.json").write_text('{"shards": []}')
    (tmp_path / "r0.ckpt").write_bytes(b"round 0")
    return _config(tmp_path)


def test_rerun_skips_and_a_new_checkpoint_reruns_what_it_feeds(tmp_path, inputs, capsys):
    out, zoo = tmp_path / "out", FakeZoo()
    doc = run_stages(_stages(inputs, out), out, {}, zoo)
    assert doc["ok"] and list(_statuses(doc)) == NAMES and set(_statuses(doc).values()) == {"ran"}
    assert zoo.calls == ["dagger", "fit", "eval", "eval"] * 2

    zoo.calls.clear()
    doc = run_stages(_stages(inputs, out), out, {}, zoo)
    assert zoo.calls == [] and set(_statuses(doc).values()) == {"skipped"}

    (round1,) = (out / "runs/fit-r1").glob("*/checkpoints/last.ckpt")
    round1.write_bytes(round1.read_bytes() + b"changed")
    doc = run_stages(_stages(inputs, out), out, {}, zoo)
    assert doc["ok"] and _statuses(doc) == {name: "skipped" if name == "dagger-r1" else "ran"
                                             for name in NAMES}
    assert (out / "runs/fit-r1.bad-1").is_dir()
    err = capsys.readouterr().err
    assert "dagger-r2: its inputs were made again (fit-r1)" in err

    zoo.calls.clear()
    (tmp_path / "r0.ckpt").write_bytes(b"round 0, trained again")
    doc = run_stages(_stages(inputs, out), out, {}, zoo)
    assert set(_statuses(doc).values()) == {"ran"} and len(zoo.calls) == len(NAMES)
    err = capsys.readouterr().err
    assert f"dagger-r1: its inputs were made again ({tmp_path / 'r0.ckpt'})" in err


def test_a_missing_initial_learner_stops_the_pipeline(tmp_path, inputs):
    (tmp_path / "r0.ckpt").unlink()
    zoo = FakeZoo()
    doc = run_stages(_stages(inputs, tmp_path / "out"), tmp_path / "out", {}, zoo)
    assert not doc["ok"] and zoo.calls == []
    first = doc["stages"][0]
    assert first["status"] == "failed" and "r0.ckpt does not exist" in first["message"]
    assert set(_statuses(doc).values()) == {"failed", "not run"}


def test_report_has_a_row_per_round(tmp_path, inputs):
    out = tmp_path / "out"
    doc = run_stages(_stages(inputs, out), out, {"config": "dagger.yaml"}, FakeZoo())
    md, page = write_reports(out, doc)
    report = md.read_text()
    for r in (1, 2):
        assert f"| DAgger rollouts, round {r} | C-VPT, scripted expert labels, β " in report
        weights = out / f"runs/fit-r{r}/run/checkpoints/last.ckpt"
        assert f"| C-VPT, DAgger round {r} | `{weights}` |" in report
        for game in ("craftax", "crafter"):
            assert f"| C-VPT, DAgger round {r} | {game} | 3 | 1.5 ± 0.5 |" in report
    assert "learner = label on 25.0%" in report and "DAgger round 2" in page.read_text()
