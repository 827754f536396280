"""Run the stages in order, skipping those whose outputs are up to date; record it all in
``pipeline.json``.

A stage is skipped when ``pipeline.json`` records it as finished with the same command and the
same inputs (the sha256 of the key file of every stage it reads, and of each input from outside
the pipeline, like a DAgger run's first learner), its output passes its check,
and its own key file still has the recorded sha256. Content hashes, not times: a stage made
again with the same bytes (data generation is deterministic) leaves the stages after it alone,
while a retrained model (a new checkpoint) makes everything that reads it run again.

Otherwise it runs. An output that fails verification is moved aside to ``<folder>.bad-N``, one
that is intact but outdated (another command, changed inputs, an interrupted training) to
``<folder>.old-N``; the message says which and why. The data commands are the exception for an
interrupted run of the same command: they finish their own folder in place (they resume).
"""

from __future__ import annotations

import json
import shlex
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path

from zoo.files import atomic_write_text, sha256_file
from zoo.pipeline.checks import Bad, Incomplete, Missing
from zoo.pipeline.config import DaggerPipelineConfig, PipelineConfig
from zoo.pipeline.dagger import dagger_plan
from zoo.pipeline.dry_run import changes, dry_plan, write_clip_init
from zoo.pipeline.stages import Keys, Stage, plan

PIPELINE_JSON = "pipeline.json"
FINISHED = ("ran", "skipped")
Call = Callable[[list[str]], str | None]  # runs one stage's argv; None, or why it failed


def run_pipeline(config: PipelineConfig | DaggerPipelineConfig, config_path: Path,
                 out: Path, dry_of: PipelineConfig | None = None) -> dict:
    """Run every enabled stage of ``config`` into ``out``; the pipeline.json document.
    ``dry_of``: the config that ``config`` is the dry run of (``zoo.pipeline.dry_run``), whose
    differences pipeline.json records under ``dry_run``."""
    dagger = isinstance(config, DaggerPipelineConfig)
    header = {"config": str(config_path), "kind": "dagger" if dagger else None}
    if dry_of is not None:
        header["dry_run"] = {"changes": changes(dry_of, config),
                             "clip_init": str(write_clip_init(out))}
        stages = dry_plan(config, out)
    else:
        stages = dagger_plan(config, out) if dagger else plan(config, out)
    return run_stages(stages, out, {**header, "settings": asdict(config)})


def run_stages(stages: list[Stage], out: Path, header: dict, call: Call | None = None) -> dict:
    """Run ``stages`` in order (``call`` runs one argv; default: ``zoo`` in this process), stop
    at the first failure; the pipeline.json document, whose ``ok`` says whether all finished."""
    call = call or call_zoo
    out.mkdir(parents=True, exist_ok=True)
    before = _previous_records(out / PIPELINE_JSON)
    doc = {
        **header, "out": str(out), "started_at": _now(), "ok": False,
        "stages": [{"name": s.name, "status": "pending" if s.enabled else "off"} for s in stages],
    }
    keys: Keys = {}
    sums: dict[str, str] = {}
    clock = time.perf_counter()
    for index, stage in enumerate(stages):
        if not stage.enabled:
            continue

        def save(record: dict, index: int = index) -> None:
            doc["stages"][index] = record
            _write_json(out / PIPELINE_JSON, doc)

        record = _run_stage(stage, keys, sums, before.get(stage.name), save, call)
        save(record)
        if record["status"] not in FINISHED:
            for later in doc["stages"][index + 1:]:
                later["status"] = "not run" if later["status"] == "pending" else later["status"]
            break
        keys[stage.name], sums[stage.name] = Path(record["key"]), record["sha256"]
    doc["ok"] = all(r["status"] in (*FINISHED, "off") for r in doc["stages"])
    doc["finished_at"], doc["seconds"] = _now(), round(time.perf_counter() - clock, 1)
    _write_json(out / PIPELINE_JSON, doc)
    return doc


def _run_stage(stage: Stage, keys: Keys, sums: dict[str, str], before: dict | None,
               save: Callable[[dict], None], call: Call) -> dict:
    """Skip ``stage`` or run it (moving a stale output aside first); its pipeline.json record."""
    clock = time.perf_counter()
    argv = stage.command(keys)
    record = {"name": stage.name, "command": "zoo " + shlex.join(argv), "argv": argv,
              "needs": {name: sums[name] for name in stage.needs}, "output": str(stage.output)}
    try:
        record["needs"].update(_fingerprints(stage.reads))
    except OSError as err:
        message = f"an input from outside the pipeline is unreadable: {err}"
        print(f"zoo pipeline: {stage.name} failed: {message}", file=sys.stderr, flush=True)
        return {**record, "status": "failed", "message": message, "seconds": 0.0}
    action, why, key = _decide(stage, record, before)
    if action == "skip":
        print(f"\n= {stage.name}: up to date, skipped ({key})", flush=True)
        return {**record, "status": "skipped", "key": str(key), "sha256": before["sha256"],
                "run_seconds": before.get("run_seconds"),
                "seconds": round(time.perf_counter() - clock, 1)}
    if action in ("bad", "old"):
        target = _move_aside(stage.output, action)
        print(f"zoo pipeline: {stage.name}: {why}; moved {stage.output} to {target} and "
              "running it again", file=sys.stderr, flush=True)
    elif action == "resume":
        print(f"zoo pipeline: {stage.name}: {why}; the same command finishes it in place",
              flush=True)
    save({**record, "status": "running"})
    print("\n$ " + record["command"], flush=True)
    message = call(argv)
    if message is None:
        try:
            if stage.finish is not None:
                stage.finish(stage.output)
            key = stage.check(stage.output)
        except (Missing, Incomplete, Bad) as err:
            message = f"its output fails verification after the run: {err}"
    seconds = round(time.perf_counter() - clock, 1)
    if message is not None:
        print(f"zoo pipeline: {stage.name} failed: {message}", file=sys.stderr, flush=True)
        return {**record, "status": "failed", "message": message, "seconds": seconds}
    return {**record, "status": "ran", "key": str(key), "sha256": sha256_file(key),
            "run_seconds": seconds, "seconds": seconds}


def _decide(stage: Stage, record: dict, before: dict | None) -> tuple[str, str, Path | None]:
    """(action, why, key file): skip, run, resume (in place), bad or old (move aside, run)."""
    same = before is not None and all(before.get(k) == record[k] for k in ("argv", "needs"))
    try:
        key = stage.check(stage.output)
    except Missing:
        return "run", "", None
    except Incomplete as err:
        if same and stage.resumable:
            return "resume", f"{err} (an interrupted run)", None
        how = "an interrupted run" if same else "made by another command"
        return "old", f"{err} ({how})", None
    except Bad as err:
        return "bad", f"its output fails verification: {err}", None
    if not same:
        if before is None:
            return "old", f"{PIPELINE_JSON} has no record of {stage.output}", None
        changed = [name for name, sha in record["needs"].items()
                   if before.get("needs", {}).get(name) != sha]
        if changed:
            return "old", f"its inputs were made again ({', '.join(changed)})", None
        return "old", f"its command changed since {stage.output} was made", None
    if before.get("status") not in FINISHED:
        why = f"its last run did not finish ({before.get('status')})"
        return ("resume", why, None) if stage.resumable else ("old", why, None)
    if sha256_file(key) != before.get("sha256"):
        return "bad", f"{key} changed since it was made (sha256 differs from the record)", None
    return "skip", "", key


def _fingerprints(paths: tuple[Path, ...]) -> dict[str, str]:
    """path -> sha256 of each input from outside the pipeline: a file's own, an export folder's
    ``sha256.txt``'s (``zoo.weights.export.checkpoint_sha256``, as DAgger manifests record it)."""
    if not paths:
        return {}
    from zoo.weights.export import checkpoint_sha256

    for path in paths:
        if not path.exists():
            raise FileNotFoundError(f"{path} does not exist")
    return {str(path): checkpoint_sha256(path) for path in paths}


def call_zoo(argv: list[str]) -> str | None:
    """Run ``zoo ARGV`` in this process; None on success, else why it failed."""
    from zoo.cli import main

    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse and LightningCLI exit on bad arguments
        code = exit_.code if isinstance(exit_.code, int) else 1
    except Exception as err:  # noqa: BLE001 - recorded in pipeline.json, traceback printed
        traceback.print_exc()
        return f"{type(err).__name__}: {err}"
    return None if code == 0 else f"`zoo {argv[0]}` exited with code {code}"


def _move_aside(path: Path, label: str) -> Path:
    """Rename ``path`` to the first free ``<path>.<label>-N``."""
    n = 1
    while (target := path.with_name(f"{path.name}.{label}-{n}")).exists():
        n += 1
    path.rename(target)
    return target


def _previous_records(path: Path) -> dict[str, dict]:
    """Stage records of the last run into this folder (none when there is no readable file)."""
    if not path.is_file():
        return {}
    try:
        return {r["name"]: r for r in json.loads(path.read_text())["stages"]}
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        print(f"zoo pipeline: {path} is unreadable ({err}); every stage runs again",
              file=sys.stderr)
        return {}


def _write_json(path: Path, doc: dict) -> None:
    """Write via a temp file and rename: a kill never leaves half a record."""
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")
