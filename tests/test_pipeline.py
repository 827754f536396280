"""`zoo pipeline`: every stage runs and lands in the report, a rerun skips them all, a damaged
output is made again with only what reads it, and the config is read strictly.

The skip/verify rules are tested on stub stages (a fake `zoo` that writes one file per stage);
the end-to-end test runs the real commands at the smallest sizes that still train and score.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
import yaml

from zoo.cli import main
from zoo.pipeline.checks import Bad, Incomplete, Missing
from zoo.pipeline.config import load_pipeline_config
from zoo.pipeline.runner import run_stages
from zoo.pipeline.stages import Stage

REPO = Path(__file__).resolve().parents[1]
QUIET = ("--trainer.logger=false --trainer.enable_progress_bar=false "
         "--trainer.enable_model_summary=false --trainer.limit_val_batches=1 ")
TINY = {
    "env": "crafter", "seed": 0, "episodes": 4, "max_steps": 150, "episodes_per_shard": 2,
    "chunk_length": 50, "workers": 1, "heldout_episodes": 1, "val_episodes": 1,
    "balance": "none", "per_unit": None, "per_shard": 500,
    "cvpt_config": str(REPO / "configs/cvpt_smoke.yaml"),
    # 2 batches of 2 TBPTT windows: 4 optimizer steps, one validation at the epoch's end
    "cvpt_args": QUIET + "--trainer.max_steps=4 --data.init_args.num_workers=0 "
    "--data.init_args.train_batches_per_epoch=2 --data.init_args.batch_size=2 "
    "--data.init_args.seq_len=16 --model.init_args.tbptt_len=8 --model.init_args.memory_len=8",
    "cclip_config": str(REPO / "configs/cclip_smoke.yaml"),
    "cclip_args": QUIET + "--trainer.max_steps=2 --trainer.val_check_interval=2 "
    "--data.init_args.num_workers=0 --data.init_args.train_batches_per_epoch=2 "
    "--data.init_args.batch_size=4 --model.init_args.warmup_steps=1 "
    "--model.init_args.vision_layers=1 --model.init_args.text_layers=1",
    "eval_episodes": 1, "eval_max_steps": 20, "retrieval": True, "steve": True,
    "csteve1_config": str(REPO / "configs/csteve1_cpu.yaml"),
    "csteve1_args": QUIET + "--trainer.max_steps=4 --trainer.max_time=null "
    "--trainer.precision=32 --model.init_args.tbptt_len=8 --model.init_args.warmup_steps=1 "
    "--model.init_args.cosine_steps=4 --data.init_args.seq_len=16 --data.init_args.batch_size=2 "
    "--data.init_args.num_workers=0 --data.init_args.val_fraction=0.3 "
    "--data.init_args.test_fraction=0.0 --data.init_args.train_batches_per_epoch=2",
    "prior_split": "train", "prior_max_pairs": None,
    "prior_config": str(REPO / "configs/prior_cpu.yaml"),
    "prior_args": QUIET + "--trainer.max_steps=2 --trainer.check_val_every_n_epoch=1 "
    "--trainer.val_check_interval=2 --model.init_args.hidden=16 --model.init_args.latent_dim=4 "
    "--model.init_args.warmup_steps=1 --data.init_args.batch_size=16",
    "task": "collect_sapling", "instruction": "obtain sapling", "task_episodes": 1, "device": "cpu",
}


def _write_config(path: Path, values: dict) -> Path:
    path.write_text(yaml.safe_dump(values))
    return path


def _statuses(out: Path) -> dict[str, str]:
    doc = json.loads((out / "pipeline.json").read_text())
    return {r["name"]: r["status"] for r in doc["stages"]}


def _flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


# --- the config ------------------------------------------------------------------------------

def test_shipped_configs_parse_and_name_existing_model_configs():
    for name in ("pipeline_quickstart.yaml", "pipeline_paper.yaml"):
        config = load_pipeline_config(REPO / "configs" / name)
        for model in (config.cvpt_config, config.cclip_config, config.csteve1_config,
                      config.prior_config):
            assert (REPO / model).is_file(), (name, model)
    assert load_pipeline_config(REPO / "configs/pipeline_paper.yaml").episodes == 20_000


@pytest.mark.parametrize(("change", "words"), [
    ({"episodez": 4}, ["unknown key(s) ['episodez']"]),
    ({"seed": None}, ["seed must be int"]),
    ({"env": "minecraft"}, ["env must be one of", "minecraft"]),
    ({"task": "fly"}, ["task must be one of", "fly"]),
])
def test_bad_config_is_one_line(tmp_path, capsys, change, words):
    values = {**TINY, **change}
    config = _write_config(tmp_path / "bad.yaml", values)
    assert main(["pipeline", "--config", str(config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"zoo pipeline: {config}") and "\n" not in err, err
    assert all(word in err for word in words), err
    assert not (tmp_path / "out").exists()


def test_missing_key_is_one_line(tmp_path, capsys):
    config = _write_config(tmp_path / "short.yaml", {k: v for k, v in TINY.items() if k != "steve"})
    assert main(["pipeline", "--config", str(config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "missing key(s) ['steve']" in err and "\n" not in err


def test_help_says_what_it_runs_and_when_it_skips(capsys):
    with pytest.raises(SystemExit):
        main(["pipeline", "--help"])
    text = capsys.readouterr().out
    for words in ("scripted expert", "C-VPT", "report.html", "pipeline.json", "skipped",
                  ".bad-N", "pipeline_paper.yaml"):
        assert words in text, words


# --- the skip / verify rules, on stub stages -----------------------------------------------

class StubZoo:
    """Stands in for `zoo`: stage NAME writes ROOT/NAME/done.txt from its inputs' contents."""

    def __init__(self, root: Path) -> None:
        self.root, self.calls, self.salt = root, [], {}
        self.fail, self.interrupt = set(), set()

    def __call__(self, argv: list[str]) -> str | None:
        _, name, *inputs = argv
        self.calls.append(name)
        out = self.root / name
        out.mkdir(exist_ok=True)
        (out / "part.txt").write_text("begun")
        if name in self.interrupt:
            raise KeyboardInterrupt
        if name in self.fail:
            return "`zoo stub` exited with code 3"
        paths = [Path(p) for p in inputs if not p.startswith("--")]
        text = name + self.salt.get(name, "") + "".join(p.read_text() for p in paths)
        (out / "done.txt").write_text(text)
        return None


def _check(out: Path) -> Path:
    if not out.exists():
        raise Missing(str(out))
    done = out / "done.txt"
    if not done.exists():
        raise Incomplete(f"{out} is partial")
    if done.read_text().startswith("corrupt"):
        raise Bad(f"{done} is corrupt")
    return done


def _stages(root: Path, resumable: bool = False, extra: str = "") -> list[Stage]:
    def stage(name: str, *needs: str) -> Stage:
        return Stage(name, needs, root / name,
                     lambda keys: ["stub", name, *(str(keys[n]) for n in needs), *extra.split()],
                     _check, resumable=resumable)

    return [stage("a"), stage("b", "a"), stage("c"), stage("d", "b")]


def test_rerun_skips_and_a_damaged_output_remakes_only_what_reads_it(tmp_path, capsys):
    zoo = StubZoo(tmp_path)
    assert run_stages(_stages(tmp_path), tmp_path, {}, zoo)["ok"]
    assert zoo.calls == ["a", "b", "c", "d"]
    zoo.calls.clear()
    assert run_stages(_stages(tmp_path), tmp_path, {}, zoo)["ok"] and zoo.calls == []
    assert set(_statuses(tmp_path).values()) == {"skipped"}

    (tmp_path / "a" / "done.txt").write_text("corrupt")  # remade with the same bytes: b, d stay
    run_stages(_stages(tmp_path), tmp_path, {}, zoo)
    assert zoo.calls == ["a"] and (tmp_path / "a.bad-1" / "done.txt").read_text() == "corrupt"
    assert "a: its output fails verification" in capsys.readouterr().err

    zoo.calls.clear()
    (tmp_path / "a" / "done.txt").write_text("corrupt")  # remade with other bytes: b, d too
    zoo.salt["a"] = "-2"
    run_stages(_stages(tmp_path), tmp_path, {}, zoo)
    assert zoo.calls == ["a", "b", "d"]
    assert _statuses(tmp_path) == {"a": "ran", "b": "ran", "c": "skipped", "d": "ran"}
    assert "b: its inputs were made again (a)" in capsys.readouterr().err
    assert (tmp_path / "b.old-1").is_dir() and (tmp_path / "a.bad-2").is_dir()

    zoo.calls.clear()
    (tmp_path / "c" / "done.txt").write_text("c, edited by hand")  # intact but not what was made
    run_stages(_stages(tmp_path), tmp_path, {}, zoo)
    assert zoo.calls == ["c"] and "sha256 differs" in capsys.readouterr().err


def test_changed_command_remakes_the_stage(tmp_path, capsys):
    zoo = StubZoo(tmp_path)
    run_stages(_stages(tmp_path), tmp_path, {}, zoo)
    zoo.calls.clear()
    run_stages(_stages(tmp_path, extra="--more"), tmp_path, {}, zoo)
    assert zoo.calls == ["a", "b", "c", "d"]
    assert "its command changed" in capsys.readouterr().err


@pytest.mark.parametrize("resumable", [False, True])
def test_an_interrupted_stage_continues(tmp_path, capsys, resumable):
    zoo = StubZoo(tmp_path)
    zoo.interrupt.add("b")
    with pytest.raises(KeyboardInterrupt):
        run_stages(_stages(tmp_path, resumable), tmp_path, {}, zoo)
    assert _statuses(tmp_path) == {"a": "ran", "b": "running", "c": "pending", "d": "pending"}
    zoo.interrupt.clear()
    zoo.calls.clear()
    assert run_stages(_stages(tmp_path, resumable), tmp_path, {}, zoo)["ok"]
    assert zoo.calls == ["b", "c", "d"]
    out = capsys.readouterr()
    if resumable:  # a data command finishes its own folder in place
        assert "finishes it in place" in out.out and not (tmp_path / "b.old-1").exists()
    else:
        assert (tmp_path / "b.old-1" / "part.txt").exists()
        assert "is partial (an interrupted run)" in out.err


def test_a_failed_stage_stops_the_pipeline(tmp_path):
    zoo = StubZoo(tmp_path)
    zoo.fail.add("b")
    doc = run_stages(_stages(tmp_path), tmp_path, {}, zoo)
    assert not doc["ok"] and zoo.calls == ["a", "b"]
    assert _statuses(tmp_path) == {"a": "ran", "b": "failed", "c": "not run", "d": "not run"}
    assert doc["stages"][1]["message"] == "`zoo stub` exited with code 3"


# --- the real commands, end to end ----------------------------------------------------------

def test_tiny_pipeline_runs_skips_and_remakes(tmp_path, capsys):
    config = _write_config(tmp_path / "tiny.yaml", TINY)
    out = tmp_path / "out"
    argv = ["pipeline", "--config", str(config), "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    for command in ("$ zoo data generate --expert scripted", "$ zoo data caption", "$ zoo fit",
                    "$ zoo eval --checkpoint", "$ zoo test", "$ zoo goals embed",
                    "$ zoo goals prior-pairs", "$ zoo eval --task collect_sapling"):
        assert command in printed, command
    doc = json.loads((out / "pipeline.json").read_text())
    assert doc["ok"] and {r["status"] for r in doc["stages"]} == {"ran"}
    assert all(r["command"].startswith("zoo ") and r["seconds"] >= 0 for r in doc["stages"])

    report = (out / "report.md").read_text()
    cvpt = json.loads((out / "eval/cvpt-craftax/report.json").read_text())["crafter_score"]
    retrieval = json.loads((out / "eval/cclip-retrieval/report.json").read_text())
    task = json.loads((out / "eval/csteve1-collect_sapling/report.json").read_text())
    assert f"| C-VPT | craftax | 1 | {cvpt['mean']:.1f} ± {cvpt['std']:.1f} |" in report
    assert f"| test | {retrieval['queries']:.0f} | {100 * retrieval['R@1']:.1f} |" in report
    assert f"| {task['success_percent']:.1f} |" in report and "| CVAE prior |" in report
    page = (out / "report.html").read_text()
    assert "data:image/png;base64," in page and "data:image/gif;base64," in page

    clock = time.perf_counter()
    assert main(argv) == 0
    assert set(_statuses(out).values()) == {"skipped"} and time.perf_counter() - clock < 30

    (prior_ckpt,) = (out / "runs/prior").glob("*/checkpoints/best-*.ckpt")
    _flip_byte(prior_ckpt)
    caption = out / "data/craftercaption"
    shard = json.loads((caption / "manifest.json").read_text())["splits"]["train"]["shards"][0]
    _flip_byte(caption / shard["name"])
    assert main(argv) == 0
    ran = {name for name, status in _statuses(out).items() if status == "ran"}
    # the captions came back byte-identical, so nothing that reads them ran again
    assert ran == {"caption", "prior", "eval-csteve1-collect_sapling"}
    assert (out / "runs/prior.bad-1").is_dir() and (out / "data/craftercaption.bad-1").is_dir()
