"""The stages of ``zoo pipeline``: each one ordinary ``zoo`` command, its output folder, the
stages it reads, and the check that says whether its output is there and intact. ``plan`` is
the suite's; ``fit_stage`` and ``score_stage`` are shared with DAgger's (``zoo.pipeline.dagger``).

Layout under ``--out``: ``data/`` (crafterplay, craftercaption, embed, prior_pairs), ``runs/``
(one folder per trained model, holding the one run LightningCLI made), ``eval/`` (one report
folder per evaluation).
"""

from __future__ import annotations

import csv
import json
import shlex
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import zoo.pipeline.checks as checks  # noqa: PLR0402 - `from zoo.pipeline import` is a cycle
from zoo.envs import ENV_NAMES
from zoo.pipeline.config import PipelineConfig

Keys = dict[str, Path]  # stage name -> key file of its verified output
RETRIEVAL_METRICS = ("R@1", "R@5", "R@10", "MeanR", "queries", "loss")


@dataclass(frozen=True)
class Stage:
    name: str
    """Key in pipeline.json and the report."""
    needs: tuple[str, ...]
    """Stages whose outputs it reads: when one of them is made again, so is this one."""
    output: Path
    """The folder it writes; moved aside when it fails verification."""
    command: Callable[[Keys], list[str]]
    """Its ``zoo`` arguments, given the key files of the stages it needs."""
    check: Callable[[Path], Path]
    """Verifies ``output`` (``zoo.pipeline.checks``) and returns its key file."""
    enabled: bool = True
    """False when the config switches it off."""
    resumable: bool = False
    """An interrupted run is finished in place by the same command (the data commands)."""
    finish: Callable[[Path], None] | None = None
    """Makes the key file from what the command wrote (the retrieval stage's report.json)."""
    reads: tuple[Path, ...] = ()
    """Inputs made outside the pipeline (a DAgger run's first learner and expert data): their
    fingerprints count with those of ``needs``."""


def plan(config: PipelineConfig, out: Path) -> list[Stage]:
    """Every stage in the order it runs; switched-off ones have ``enabled`` False."""
    data, runs, evals = out / "data", out / "runs", out / "eval"
    play, caption = data / "crafterplay", data / "craftercaption"
    return [
        Stage("generate", (), play, lambda keys: _generate(config, play), checks.crafterplay,
              resumable=True),
        Stage("caption", ("generate",), caption, lambda keys: _caption(config, play, caption),
              checks.craftercaption, resumable=True),
        fit_stage("cvpt", config.cvpt_config, config.cvpt_args, runs, ("generate",),
                  # sources=null: the pipeline's own data replaces a config's several sources
                  lambda keys: [f"--data.init_args.root={play}", "--data.init_args.sources=null"]),
        fit_stage("cclip", config.cclip_config, config.cclip_args, runs, ("caption",),
                  lambda keys: [f"--data.init_args.root={caption}"]),
        *(_score(config, evals, "scripted", game) for game in ENV_NAMES),
        *(_score(config, evals, "cvpt", game) for game in ENV_NAMES),
        _retrieval(config, evals / "cclip-retrieval", caption),
        *_steve(config, data, runs, evals, play, caption),
    ]


def _generate(config: PipelineConfig, play: Path) -> list[str]:
    return ["data", "generate", "--expert", "scripted", "--env", config.env,
            "--episodes", str(config.episodes), "--max-steps", str(config.max_steps),
            "--seed", str(config.seed), "--episodes-per-shard", str(config.episodes_per_shard),
            "--chunk-length", str(config.chunk_length), "--workers", str(config.workers),
            "--out", str(play)]


def _caption(config: PipelineConfig, play: Path, caption: Path) -> list[str]:
    quota = [] if config.per_unit is None else ["--per-unit", str(config.per_unit)]
    return ["data", "caption", "--src", str(play), "--out", str(caption),
            "--seed", str(config.seed), "--balance", config.balance, *quota,
            "--heldout-episodes", str(config.heldout_episodes),
            "--val-episodes", str(config.val_episodes), "--per-shard", str(config.per_shard)]


def fit_stage(name: str, config_path: str, args: str, runs: Path, needs: tuple[str, ...],
              wiring: Callable[[Keys], list[str]], enabled: bool = True, *,
              kind: str | None = None, weights: str = "best-*.ckpt",
              reads: tuple[Path, ...] = ()) -> Stage:
    """``zoo fit`` into ``runs/name``: the config, then the user's overrides, then the paths
    that wire it to the other stages (those win). Its key is the run's ``checkpoints/<weights>``
    (default: the one validation chose), rebuilt as a ``kind`` network (default: ``name``)."""
    output = runs / name

    def command(keys: Keys) -> list[str]:
        return ["fit", f"--config={config_path}", *shlex.split(args),
                f"--trainer.default_root_dir={output}", *wiring(keys)]

    check = partial(checks.checkpoint, kind=kind or name, pattern=weights)
    return Stage(name, needs, output, command, check, enabled, reads=reads)


def score_stage(name: str, output: Path, needs: tuple[str, ...],
                agent: Callable[[Keys], list[str]], options: list[str]) -> Stage:
    """Crafter Score: ``zoo eval AGENT OPTIONS --out OUTPUT``, verified by its report."""
    return Stage(name, needs, output,
                 lambda keys: ["eval", *agent(keys), *options, "--out", str(output)],
                 partial(checks.report, field="crafter_score"))


def _score(config: PipelineConfig, evals: Path, agent: str, game: str) -> Stage:
    """Crafter Score of the scripted expert (the reference row, state only) or the C-VPT."""
    options = ["--env", game, "--episodes", str(config.eval_episodes),
               "--max-steps", str(config.eval_max_steps), "--seed", str(config.seed)]
    if agent == "scripted":
        return score_stage(f"eval-scripted-{game}", evals / f"scripted-{game}", (),
                           lambda keys: ["--agent", "scripted", "--no-gif"], options)
    return score_stage(f"eval-cvpt-{game}", evals / f"cvpt-{game}", ("cvpt",),
                       lambda keys: ["--checkpoint", str(keys["cvpt"])], options)


def _retrieval(config: PipelineConfig, output: Path, caption: Path) -> Stage:
    """``zoo test`` of C-CLIP on the held-out episodes, its metrics logged to a CSV file."""

    def command(keys: Keys) -> list[str]:
        return ["test", f"--config={config.cclip_config}", *shlex.split(config.cclip_args),
                f"--ckpt_path={keys['cclip']}", f"--data.init_args.root={caption}",
                f"--trainer.default_root_dir={output}",
                "--trainer.logger=lightning.pytorch.loggers.CSVLogger",
                "--trainer.logger.init_args.save_dir=.", "--trainer.logger.init_args.name=csv"]

    return Stage("eval-cclip-retrieval", ("cclip", "caption"), output, command,
                 partial(checks.report, field="R@1"), config.retrieval,
                 finish=_retrieval_report)


def _retrieval_report(output: Path) -> None:
    """report.json from the test run's metrics.csv (Lightning prints the metrics but returns
    nothing to ``zoo test``'s caller)."""
    found = sorted(output.glob("*/csv/*/metrics.csv"))
    if not found:
        raise checks.Bad(f"{output}: zoo test wrote no metrics.csv")
    with found[-1].open() as f:
        rows = list(csv.DictReader(f))
    values = {k: v for row in rows for k, v in row.items() if v not in ("", None)}
    metrics = {name: float(values[f"test/{name}"]) for name in RETRIEVAL_METRICS
               if f"test/{name}" in values}
    if "R@1" not in metrics:
        raise checks.Bad(f"{found[-1]} has no test/R@1: the test split needs at least one group "
                         "of 64 clips (caption more held-out episodes)")
    report = {"split": "test", **metrics, "metrics_csv": str(found[-1])}
    (output / "report.json").write_text(json.dumps(report, indent=1) + "\n")


def _steve(config: PipelineConfig, data: Path, runs: Path, evals: Path, play: Path,
           caption: Path) -> list[Stage]:
    """Goal embeddings -> C-Steve-1, prior pairs -> prior, then one instruction task."""
    embed, pairs = data / "embed", data / "prior_pairs"
    task_out = evals / f"csteve1-{config.task}"

    def width(record: Path) -> str:
        """C-CLIP's embedding width, as an embedding manifest or a pairs sidecar records it."""
        return str(json.loads(record.read_text())["embed_dim"])

    def pairs_argv(keys: Keys) -> list[str]:
        most = config.prior_max_pairs
        subset = [] if most is None else ["--max-pairs", str(most)]
        return ["goals", "prior-pairs", "--checkpoint", str(keys["cclip"]), "--src", str(caption),
                "--split", config.prior_split, *subset, "--paraphrases",
                "--seed", str(config.seed), "--device", config.device,
                "--out", str(pairs / "pairs.npz")]

    def prior_wiring(keys: Keys) -> list[str]:
        pairs_file = keys["prior-pairs"]
        return [f"--data.init_args.root={pairs_file}",
                f"--model.init_args.embed_dim={width(pairs_file.with_suffix('.json'))}"]

    def task_argv(keys: Keys) -> list[str]:
        return ["eval", "--task", config.task, "--checkpoint", str(keys["csteve1"]),
                "--cclip", str(keys["cclip"]), "--prior", str(keys["prior"]),
                "--instruction", config.instruction, "--env", config.env,
                "--episodes", str(config.task_episodes), "--seed", str(config.seed),
                "--out", str(task_out)]

    on = config.steve
    return [
        Stage("embed", ("generate", "cclip"), embed,
              lambda keys: ["goals", "embed", "--checkpoint", str(keys["cclip"]), "--src",
                            str(play), "--out", str(embed), "--device", config.device],
              partial(checks.embeddings, play=play), on, resumable=True),
        fit_stage("csteve1", config.csteve1_config, config.csteve1_args, runs,
                  ("generate", "embed", "cvpt"),
                  lambda keys: [f"--data.init_args.root={play}",
                                f"--data.init_args.embeddings={embed}",
                                f"--model.init_args.backbone={keys['cvpt']}",
                                f"--model.init_args.goal_dim={width(keys['embed'])}"], on),
        Stage("prior-pairs", ("caption", "cclip"), pairs, pairs_argv, checks.prior_pairs, on),
        fit_stage("prior", config.prior_config, config.prior_args, runs, ("prior-pairs",),
                  prior_wiring, on),
        Stage(f"eval-csteve1-{config.task}", ("csteve1", "cclip", "prior"), task_out, task_argv,
              partial(checks.report, field="success_percent"), on),
    ]
