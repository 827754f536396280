"""Bad input to `zoo` gets one line naming the problem, never a traceback; normal use prints no
noise from the libraries underneath (issue 31, section 3)."""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest

from zoo.cli import main
from zoo.envs import Step
from zoo.envs.schema import empty_state

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "configs" / "cvpt_smoke.yaml"
NOISE = ("💡 Tip", "anonymous setting", "LeafSpec", "dirpath has changed", "git root")


def _zoo(*argv: str, timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """``zoo ARGV`` in a fresh interpreter, as a user runs it."""
    env = {**os.environ, "WANDB_MODE": "offline"}
    return subprocess.run([sys.executable, "-m", "zoo.cli", *argv], cwd=REPO, env=env, check=False,
                          text=True, timeout=timeout, **kwargs)


class ShortGame:
    """A 1-env stand-in GameEnv whose episodes last ``length`` steps."""

    name = "short"
    num_envs = 1

    def __init__(self, length: int = 5) -> None:
        self.length, self.t = length, 0

    def _observe(self) -> Step:
        frames = np.zeros((1, 144, 144, 3), np.uint8)
        done = np.array([self.t >= self.length])
        return Step(frames, empty_state(1), np.zeros(1, np.float32), done)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        self.t = 0
        return self._observe()

    def step(self, actions: np.ndarray) -> Step:
        self.t += 1
        return self._observe()


def test_data_caption_with_a_missing_src_is_one_line(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "no-such-play"
    assert main(["data", "caption", "--src", str(missing), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("zoo data caption: ") and str(missing) in err[0]


def test_output_into_a_closed_pipe_ends_quietly() -> None:
    """`zoo captions list | head -1`, made deterministic: the reading end is closed first."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        done = _zoo("captions", "list", timeout=120, stdout=write_end, stderr=subprocess.PIPE)
    finally:
        os.close(write_end)
    assert done.stderr == "" and done.returncode == 1


def test_fit_with_a_missing_data_root_stops_before_wandb_and_the_model(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-play"
    done = _zoo("fit", f"--config={CONFIG}", f"--data.init_args.root={missing}",
                f"--trainer.default_root_dir={tmp_path / 'runs'}", timeout=280,
                capture_output=True)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.splitlines() == [
        f"zoo fit: data.init_args.root={missing}: no such file or folder"
    ]
    assert not (tmp_path / "runs").exists()


def test_data_paths_are_checked_by_field_and_urls_left_to_fsspec(tmp_path: Path) -> None:
    from jsonargparse import Namespace

    from lit_models.cli import DataNotFoundError, check_data_paths

    def data(**init_args) -> Namespace:
        return Namespace(class_path="datamodules.crafterplay.CrafterPlayDataModule",
                         init_args=Namespace(**init_args))

    check_data_paths(data(root="https://host/crafterplay/", sources=None))
    check_data_paths(data(root=str(tmp_path), embeddings=str(tmp_path)))
    sources = [{"root": str(tmp_path)}, {"root": str(tmp_path / "dagger"), "weight": 1}]
    with pytest.raises(DataNotFoundError, match=r"^data\.init_args\.sources\[1\]\.root=.*dagger"):
        check_data_paths(data(root=None, sources=sources))
    with pytest.raises(DataNotFoundError, match=r"^data\.init_args\.embeddings="):
        check_data_paths(data(root=str(tmp_path), embeddings=str(tmp_path / "embed")))


def test_eval_rate_is_timed_from_the_end_of_the_first_step(monkeypatch, capsys) -> None:
    """Craftax compiles its step on the first call (seconds); the bar's rate must not carry it
    to the end of a short evaluation (it showed steps_per_s=0)."""
    from zoo.agents import RandomAgent
    from zoo.eval.rollout import evaluate

    clock = types.SimpleNamespace(now=0.0)
    fake_time = types.SimpleNamespace(perf_counter=lambda: clock.now)
    monkeypatch.setattr("zoo.eval.rollout.time", fake_time)

    class CompilingGame(ShortGame):
        def step(self, actions: np.ndarray) -> Step:
            clock.now += 10.0 if clock.now == 0 else 0.001  # compile once, then 1,000 steps/s
            return super().step(actions)

    evaluate(RandomAgent(1), CompilingGame(), 3, seed=0, record_gif_episode=None)
    rates = re.findall(r"steps_per_s=(\d+)", capsys.readouterr().err)
    assert rates and 900 <= int(rates[-1]) <= 1100


def test_play_shows_a_bar_of_steps(capsys) -> None:
    from zoo.agents import RandomAgent
    from zoo.eval.play import play_episode

    result = play_episode(RandomAgent(1), ShortGame(5), 0, None, 50, progress=True)
    assert len(result["actions"]) == 5
    assert re.search(r"play: +10%\|.*\| 5/50", capsys.readouterr().err)


class _StopBeforeWandb(Exception):
    pass


def test_wandb_starts_without_the_anonymous_setting_in_an_existing_folder(
    tmp_path: Path, monkeypatch
) -> None:
    """Lightning's WandbLogger passes anonymous=None, which wandb warns about; and wandb warns
    about a 'git root' that does not exist when its folder is not made yet."""
    import wandb

    given: list[dict] = []

    def init(**kwargs):
        given.append({**kwargs, "dir_exists": Path(kwargs["dir"]).is_dir()})
        raise _StopBeforeWandb

    monkeypatch.setattr(wandb, "init", init)
    play = tmp_path / "play"
    play.mkdir()  # the run stops when W&B starts, before the data is read
    with pytest.raises(_StopBeforeWandb):
        main(["fit", f"--config={CONFIG}", f"--data.init_args.root={play}",
              f"--trainer.default_root_dir={tmp_path / 'runs'}"])
    (kwargs,) = given
    assert "anonymous" not in kwargs and kwargs["dir_exists"]


@pytest.fixture(scope="module")
def crafterplay(tmp_path_factory) -> Path:
    from zoo.agents import dataset_agent
    from zoo.data.generate import GenerationConfig, generate

    out = tmp_path_factory.mktemp("crafterplay")
    config = GenerationConfig(expert="random", episodes=6, seed=1, env="crafter",
                              episodes_per_shard=2, chunk_length=32, max_steps=80)
    generate(config, out, progress=False, build_agent=dataset_agent)
    return out


def test_fit_then_validate_from_its_checkpoint_print_no_library_notices(
    crafterplay: Path, tmp_path: Path
) -> None:
    """Lightning's litlogger tip (a log record), torch's LeafSpec warning (raised inside
    Lightning) and, on validating a checkpoint, ModelCheckpoint's 'dirpath has changed'."""
    from lit_models.cli import run_lightning_cli

    records: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: records.append(record.getMessage())
    logging.getLogger("lightning.pytorch").addHandler(handler)
    args = [f"--config={CONFIG}", f"--trainer.default_root_dir={tmp_path}",
            "--trainer.logger=false", "--trainer.enable_progress_bar=false",
            "--trainer.enable_model_summary=false", "--trainer.limit_val_batches=1",
            f"--data.init_args.root={crafterplay}", "--data.init_args.seq_len=8",
            "--data.init_args.batch_size=2", "--data.init_args.num_workers=0",
            "--data.init_args.val_fraction=0.3", "--data.init_args.train_batches_per_epoch=1",
            "--model.init_args.tbptt_len=4", "--model.init_args.memory_len=4"]
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cli = run_lightning_cli(["fit", *args, "--trainer.max_steps=1"])
            (last,) = Path(cli.trainer.default_root_dir).glob("checkpoints/last.ckpt")
            run_lightning_cli(["validate", *args, f"--ckpt_path={last}"])
    finally:
        logging.getLogger("lightning.pytorch").removeHandler(handler)
    printed = records + [str(w.message) for w in caught]
    assert any("Restoring states" in line for line in printed)  # the capture works
    assert not [line for line in printed if any(noise in line for noise in NOISE)]
