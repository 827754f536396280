"""``report.md`` and a self-contained ``report.html`` of one pipeline run.

Every number is read back from what the stages wrote (manifests, checkpoints, report.json
files), never from the pipeline's memory, so a report rebuilt after a resumed run shows what
is on disk. The tables are built once and rendered twice; the HTML embeds the achievement plots
and episode GIFs as base64 ``<img>`` so the one file can be mailed or attached to an issue.
Tables are found by stage name, so one report serves both plans: the suite's and DAgger's
(``dagger-rN`` rollouts, ``fit-rN`` weights, ``eval-rN-GAME`` scores: one row per round).
"""

from __future__ import annotations

import base64
import html
import json
import re
from dataclasses import dataclass
from pathlib import Path

from zoo.envs import ENV_NAMES

AGENT_TITLES = {"scripted": "scripted expert", "cvpt": "C-VPT"}
ROUND_TITLE = "C-VPT, DAgger round {}"
Figure = tuple[str, Path]  # (caption, image file)


@dataclass(frozen=True)
class Table:
    title: str
    headers: tuple[str, ...]
    rows: list[tuple[str, ...]]


def write_reports(out: Path, doc: dict) -> tuple[Path, Path]:
    """Write ``out/report.md`` and ``out/report.html`` for the pipeline.json document ``doc``."""
    records = {r["name"]: r for r in doc["stages"]}
    tables = [t for t in (_stages(doc), _data(records), _models(records), _scores(records),
                          _retrieval(records), _task(records)) if t.rows]
    figures = _figures(records)
    state = "all stages finished" if doc["ok"] else "INCOMPLETE"
    dry = " as a DRY RUN (2 steps per fit on a few episodes: shapes, not results)" if doc.get(
        "dry_run") else ""
    summary = (f"config `{doc['config']}`{dry}, started {doc['started_at']}, "
               f"{doc['seconds']:.0f} s, {state}")
    md, page = out / "report.md", out / "report.html"
    md.write_text(_markdown(out, summary, tables, figures))
    page.write_text(_html(out, summary, tables, figures))
    return md, page


def _json(record: dict | None) -> dict | None:
    """The stage's report.json, when it finished."""
    if record is None or record.get("status") not in ("ran", "skipped"):
        return None
    return json.loads(Path(record["key"]).read_text())


def _pm(stat: dict) -> str:
    return f"{stat['mean']:.1f} ± {stat['std']:.1f}"


def _stages(doc: dict) -> Table:
    rows = []
    for r in doc["stages"]:
        seconds = r.get("seconds")
        if r["status"] == "skipped" and r.get("run_seconds") is not None:
            seconds = f"{r['run_seconds']:.1f} (earlier run)"
        rows.append((r["name"], r["status"], "" if seconds is None else str(seconds),
                     f"`{r['command']}`" if "command" in r else ""))
    return Table("Stages", ("stage", "status", "seconds", "command"), rows)


def _round(name: str, prefix: str = "") -> str | None:
    """N of a DAgger round's name ``{prefix}rN`` (``fit-r2``); None for any other name."""
    match = re.fullmatch(rf"{re.escape(prefix)}r(\d+)", name)
    return match and match.group(1)


def _crafterplay(title: str, made_by: str, manifest: dict) -> tuple[str, ...]:
    shards = manifest["shards"]
    return (title, made_by, str(sum(s["episodes"] for s in shards)),
            str(sum(s["steps"] for s in shards)),
            f"{len(shards)} shards, {sum(s['bytes'] for s in shards) / 1e6:.1f} MB")


def _rollouts(n: str, manifest: dict) -> tuple[str, ...]:
    """A DAgger round's shards: who played, and how often the learner chose the expert's label."""
    config, shards = manifest["config"], manifest["shards"]
    dagger = config["dagger"]
    steps = sum(s["steps"] for s in shards)
    agreed = sum(s["dagger"]["learner_agreement"] * s["steps"] for s in shards) / max(steps, 1)
    return _crafterplay(f"DAgger rollouts, round {n}",
                        f"C-VPT, {config['expert']} expert labels, β {dagger['beta']} per "
                        f"{dagger['mix']}, {config['env']}; learner = label on {agreed:.1%}",
                        manifest)


def _data(records: dict) -> Table:
    rows = []
    play = _json(records.get("generate"))
    if play is not None:
        rows.append(_crafterplay(
            "CrafterPlay", f"{play['config']['expert']} expert, {play['config']['env']}", play))
    rows += [_rollouts(n, manifest) for name, record in records.items()
             if (n := _round(name, "dagger-")) and (manifest := _json(record)) is not None]
    caption = _json(records.get("caption"))
    if caption is not None:
        for split, meta in caption["splits"].items():
            rows.append((f"CrafterCaption {split}", f"balance {caption['balance']}",
                         str(meta["episodes"]), f"{meta['samples']} clips",
                         f"{len(meta['shards'])} shards"))
    return Table("Data", ("dataset", "made by", "episodes", "steps / clips", "files"), rows)


def _checkpoint_numbers(path: Path) -> tuple[int, str, str, int]:
    """(step, monitor, best score, last step) of a ``zoo fit`` checkpoint (best or last)."""
    from zoo.weights.checkpoint_io import read_torch_file

    best = read_torch_file(path, mmap=True)
    last_path = path.with_name("last.ckpt")
    last = read_torch_file(last_path, mmap=True) if last_path.exists() else best
    monitored = [s for s in best["callbacks"].values() if s.get("monitor")]
    monitor, score = ("", "") if not monitored else (
        monitored[0]["monitor"], f"{float(monitored[0]['best_model_score']):.4g}")
    return best["global_step"], monitor, score, last["global_step"]


def _models(records: dict) -> Table:
    rows = []
    titles = {"cvpt": "C-VPT", "cclip": "C-CLIP", "csteve1": "C-Steve-1", "prior": "CVAE prior",
              **{name: ROUND_TITLE.format(n) for name in records if (n := _round(name, "fit-"))}}
    for name, title in titles.items():
        record = records.get(name)
        if record is None or record.get("status") not in ("ran", "skipped"):
            continue
        step, monitor, score, last = _checkpoint_numbers(Path(record["key"]))
        rows.append((title, f"`{record['key']}`", str(step), str(last), monitor, score))
    headers = ("model", "checkpoint (suite: best by validation; DAgger: last)", "its step",
               "steps trained", "validation metric", "best value")
    return Table("Models", headers, rows)


def _scores(records: dict) -> Table:
    """Every ``eval-WHO-GAME`` stage of a game (not a task, not retrieval), in stage order."""
    rows = []
    for name, record in records.items():
        who, _, game = name.removeprefix("eval-").rpartition("-")
        if not name.startswith("eval-") or game not in ENV_NAMES or (rep := _json(record)) is None:
            continue
        title = AGENT_TITLES.get(who) or (ROUND_TITLE.format(n) if (n := _round(who)) else who)
        rows.append((title, rep["env"], str(rep["episodes"]), _pm(rep["crafter_score"]),
                     _pm(rep["normalized_return"]), f"{rep['episode_length']['mean']:.0f}",
                     f"{rep['episode_end_percent']['survived']:.0f}"))
    headers = ("agent", "game", "episodes", "Crafter Score (%)", "Return (%)", "mean length",
               "survived (%)")
    return Table("Crafter Score (mean ± std over chunks)", headers, rows)


def _retrieval(records: dict) -> Table:
    rep = _json(records.get("eval-cclip-retrieval"))
    rows = [] if rep is None else [(
        rep["split"], f"{rep['queries']:.0f}",
        *(f"{100 * rep[k]:.1f}" for k in ("R@1", "R@5", "R@10")), f"{rep['MeanR']:.2f}",
    )]
    return Table("C-CLIP video -> text retrieval (groups of 64 clips)",
                 ("split", "queries", "R@1 (%)", "R@5 (%)", "R@10 (%)", "MeanR"), rows)


def _task(records: dict) -> Table:
    rows = []
    for name, record in records.items():
        if not name.startswith("eval-csteve1-") or (rep := _json(record)) is None:
            continue
        low, high = rep["wilson95_percent"]
        median = rep["median_steps_to_success"]
        rows.append((rep["task"], rep["instruction_mode"], rep["env"], str(rep["episodes"]),
                     f"{rep['success_percent']:.1f}", f"{low:.1f}-{high:.1f}",
                     "-" if median is None else f"{median:.0f}"))
    headers = ("task", "given", "game", "episodes", "success (%)", "Wilson 95%",
               "median steps")
    return Table("C-Steve-1 task", headers, rows)


def _figures(records: dict) -> list[Figure]:
    """(caption, file) of every achievement plot and episode GIF the evaluations wrote."""
    out = []
    for name, record in records.items():
        if name.startswith("eval-") and record.get("status") in ("ran", "skipped"):
            folder = Path(record["output"])
            out += [(f"{name}: {file}", folder / file)
                    for file in ("achievements.png", "episode.gif") if (folder / file).exists()]
    return out


def _markdown(out: Path, summary: str, tables: list[Table], figures: list[Figure]) -> str:
    lines = [f"# crafter-zoo pipeline: {out}", "", summary, ""]
    for table in tables:
        lines += [f"## {table.title}", "", "| " + " | ".join(table.headers) + " |",
                  "|" + "---|" * len(table.headers)]
        lines += ["| " + " | ".join(row) + " |" for row in table.rows]
        lines.append("")
    if figures:
        lines += ["## Figures", ""]
        lines += [f"![{caption}]({path.relative_to(out)})" for caption, path in figures]
        lines.append("")
    return "\n".join(lines)


STYLE = ("body{font-family:sans-serif;max-width:70em;margin:2em auto}"
         "table{border-collapse:collapse;margin-bottom:1.5em}"
         "td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}"
         "code{font-size:85%}figure{display:inline-block;margin:.5em}")


def _cell(text: str) -> str:
    """A markdown cell in HTML: backquoted text becomes <code>."""
    if len(text) > 1 and text.startswith("`") and text.endswith("`"):
        return f"<code>{html.escape(text[1:-1])}</code>"
    return html.escape(text)


def _html(out: Path, summary: str, tables: list[Table], figures: list[Figure]) -> str:
    title = html.escape(f"crafter-zoo pipeline: {out}")
    head = f"<meta charset='utf-8'><title>{title}</title><style>{STYLE}</style>"
    parts = [f"<!doctype html><html><head>{head}</head><body><h1>{title}</h1>",
             f"<p>{html.escape(summary).replace('`', '')}</p>"]
    for table in tables:
        head = "".join(f"<th>{html.escape(h)}</th>" for h in table.headers)
        body = "".join("<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in row) + "</tr>"
                       for row in table.rows)
        parts.append(f"<h2>{html.escape(table.title)}</h2><table><tr>{head}</tr>{body}</table>")
    if figures:
        parts.append("<h2>Figures</h2>")
    for caption, path in figures:
        mime = "image/gif" if path.suffix == ".gif" else "image/png"
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        parts.append(f"<figure><img src='data:{mime};base64,{data}' alt='{html.escape(caption)}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
