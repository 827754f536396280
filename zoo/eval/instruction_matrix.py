"""The instruction matrix (``zoo tables instructions``): does an agent do what it is told, rather
than what it does anyway?

Rows are instructions (each of ``COLUMNS``, then no instruction), columns the achievements those
instructions ask for; a cell counts the episodes where the column's achievement first happens
within the first L steps. Every row plays the same N worlds (episode j seeded from (seed, j),
as ``zoo eval`` does), so a column compares the instructions on equal terms: an agent that
follows them peaks on its own row, and its own row stands above the no-instruction one (the
zero goal for C-Steve-1, normal play for the scripted expert). The best *other* instruction of
a column (the row maximizing it among the other instructions) is the specificity control: an
agent that only reacts to "some instruction" does as well there as on its own.

Each row is one batched ``zoo.eval.rollout.evaluate`` run of N episodes capped at L steps,
saved as OUT/<game>/<row>.json (the unlock step of every achievement per episode); a rerun
reads the rows already saved, and refuses rows saved under another setting.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from zoo.agents import AgentSpec
from zoo.agents.base import InstructableAgent
from zoo.envs import ACHIEVEMENT_NAMES, Achievement, make_env
from zoo.envs.base import GameEnv, Step
from zoo.envs.tasks.specs import DRINK_SUB, PLANT, SAPLING, TABLE, WOOD_PICKAXE, SubTask
from zoo.eval.play import inference_meta
from zoo.eval.rollout import evaluate
from zoo.eval.stats import disjoint_above, p_text, two_proportion_p
from zoo.eval.task_eval import wilson_interval
from zoo.files import atomic_write_text

# The default rows and columns: each instruction (the exact caption of the project's task
# suites; "obtain wood" is the caption of collect_wood) and the achievement it asks for.
COLUMNS: tuple[SubTask, ...] = (
    SAPLING, DRINK_SUB, TABLE, SubTask(Achievement.COLLECT_WOOD, "obtain wood"), PLANT,
    WOOD_PICKAXE,
)
NO_INSTRUCTION = "no instruction"
VERDICT_KEYS = (  # the per-game counts of report.json, one per column test of ``verdict``
    "own_is_max", "own_is_max_tied", "above_none", "separated_from_none", "below_none",
    "worse_than_none", "separated_from_best_other",
)
Counts = dict[str, dict[str, int]]  # row label -> achievement name -> episodes
HELP = "the instruction matrix: each instruction and none, on the same worlds"
DESCRIPTION = (
    f"{HELP}, against the achievements they ask for. A cell counts the episodes where its "
    "column's achievement first happens within --max-steps steps (Wilson 95% interval). Rows: "
    f"{', '.join(repr(c.instruction) for c in COLUMNS)}, then {NO_INSTRUCTION} (C-Steve-1's zero "
    "goal, the scripted expert's normal play); episode j of every row is seeded from (--seed, "
    "j). Writes OUT/report.json, OUT/report.md (the matrix and the verdict: in how many "
    "columns the agent's own instruction is the maximum, has a disjoint 95% interval above no "
    "instruction's, or below it; per column the two-proportion test p-value against no "
    "instruction) and OUT/matrix.png; each row is saved as OUT/<game>/<row>.json, and a rerun "
    "reads the saved rows instead of playing them."
)
HORIZONS = "also score the same episodes within their first H steps (each H <= --max-steps)"


@dataclass(frozen=True)
class Setting:
    """What every row of a matrix shares: a row saved under another setting is not reused.
    The agent's guidance and temperature left None stand for what ``make_instructable`` finds
    (the ones its export records)."""

    agent: AgentSpec
    seed: int
    episodes: int
    max_steps: int

    def record(self) -> dict:
        """What a saved row and the report say it was played with (the agent's files with
        their sha256)."""
        return {"agent": self.agent.record(), "seed": self.seed, "episodes": self.episodes,
                "max_steps": self.max_steps}


def pick_columns(instructions: Sequence[str] | None) -> tuple[SubTask, ...]:
    """The columns of the named instructions, in ``COLUMNS``' order (None: all)."""
    if instructions is None:
        return COLUMNS
    known = {c.instruction: c for c in COLUMNS}
    unknown = [t for t in instructions if t not in known]
    if unknown:
        raise ValueError(f"unknown instruction {unknown[0]!r}; the matrix knows {sorted(known)}")
    return tuple(c for c in COLUMNS if c.instruction in instructions)


def row_labels(columns: Sequence[SubTask]) -> list[str]:
    return [c.instruction for c in columns] + [NO_INSTRUCTION]


def interval(k: int, n: int) -> list[float]:
    """Wilson 95% interval of k/n, in percent."""
    low, high = wilson_interval(k, n)
    return [100.0 * low, 100.0 * high]


def count_matrix(
    rows: dict[str, list[dict[str, int]]], columns: Sequence[SubTask], max_steps: int
) -> Counts:
    """Per row and column, the episodes (each a dict achievement -> first unlock step) where
    the column's achievement first happens at a step <= ``max_steps``."""
    names = [ACHIEVEMENT_NAMES[c.achievement] for c in columns]
    return {label: {a: sum(1 <= e.get(a, -1) <= max_steps for e in episodes) for a in names}
            for label, episodes in rows.items()}


def verdict(counts: Counts, episodes: int, columns: Sequence[SubTask]) -> list[dict]:
    """Per column, its own instruction against the other rows. A tie at the top counts as the
    column maximum (``own_is_max_tied`` says so); "separated" (and ``worse_than_none``) means
    disjoint Wilson 95% intervals, much stricter than a 95% test, so ``p_two_proportion_vs_none``
    gives the two-sided two-proportion test against no instruction too; ``above_none`` and
    ``below_none`` compare counts alone."""
    result = []
    for column in columns:
        a, own_label = ACHIEVEMENT_NAMES[column.achievement], column.instruction
        own, none = counts[own_label][a], counts[NO_INSTRUCTION][a]
        others = {r: c[a] for r, c in counts.items() if r not in (own_label, NO_INSTRUCTION)}
        best = max(others.values(), default=None)
        top = max(c[a] for r, c in counts.items() if r != own_label)
        own_ci, none_ci = interval(own, episodes), interval(none, episodes)
        result.append({
            "achievement": a, "instruction": own_label, "own": own, "no_instruction": none,
            "best_other": [r for r, k in others.items() if k == best], "best_other_count": best,
            "own_is_max": own >= top, "own_is_max_tied": own == top,
            "above_none": own > none, "separated_from_none": disjoint_above(own_ci, none_ci),
            "below_none": own < none, "worse_than_none": disjoint_above(none_ci, own_ci),
            "separated_from_best_other": best is not None
            and disjoint_above(own_ci, interval(best, episodes)),
            "p_two_proportion_vs_none": two_proportion_p(own, episodes, none, episodes),
        })
    return result


def summarize(columns: list[dict]) -> dict[str, int]:
    """How many columns pass each test of ``verdict``."""
    return {"columns": len(columns), **{key: sum(c[key] for c in columns) for key in VERDICT_KEYS}}


def verdict_line(game: str, s: dict[str, int]) -> str:
    return (
        f"{game}: own instruction is the column maximum in {s['own_is_max']} of {s['columns']} "
        f"columns ({s['own_is_max_tied']} tied); above no instruction in {s['above_none']}, "
        f"disjoint 95% intervals in {s['separated_from_none']}; below no instruction in "
        f"{s['below_none']}, disjoint 95% intervals (worse told than untold) in "
        f"{s['worse_than_none']}; disjoint 95% intervals above the best other instruction in "
        f"{s['separated_from_best_other']}"
    )


def check_horizons(horizons: Sequence[int], max_steps: int) -> tuple[int, ...]:
    """The extra horizons, sorted and without L itself; ValueError if one is longer than L
    (the rows stop there)."""
    longer = [h for h in horizons if not 1 <= h <= max_steps]
    if longer:
        raise ValueError(f"--horizons {longer[0]}: the rows play {max_steps} steps "
                         f"(--max-steps); give horizons from 1 to {max_steps}")
    return tuple(sorted(set(horizons) - {max_steps}))


def score(rows: dict[str, list[dict[str, int]]], columns: Sequence[SubTask], episodes: int,
          horizon: int, game: str) -> dict:
    """One game's counts, per-column verdict, summary and Wilson cells within ``horizon``."""
    counts = count_matrix(rows, columns, horizon)
    per_column = verdict(counts, episodes, columns)
    summary = summarize(per_column)
    return {
        "counts": counts, "columns": per_column, "verdict": summary,
        "verdict_line": verdict_line(game, summary),
        "wilson95_percent": {r: {a: interval(k, episodes) for a, k in c.items()}
                             for r, c in counts.items()},
    }


class _Told:
    """Gives the agent one instruction (None: none) after every reset: C-Steve-1 keeps an
    instruction across episodes and the scripted expert drops it, so each needs telling."""

    def __init__(self, inner: InstructableAgent, instruction: str | None, num_envs: int):
        self.inner, self.instruction, self.num_envs = inner, instruction, num_envs
        self.name, self.needs_pixels = inner.name, inner.needs_pixels

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.inner.reset(seeds, mask)
        self.inner.instruct([self.instruction] * self.num_envs, mask)

    def act(self, step: Step) -> np.ndarray:
        return self.inner.act(step)


def make_instructable(
    setting: Setting, num_envs: int, columns: Sequence[SubTask]
) -> tuple[InstructableAgent, Setting]:
    """The setting's agent (by name, or the one its checkpoint holds) and the setting with its
    name, guidance scale and temperature filled in; ValueError (one line) if it cannot play
    every row of ``columns``."""
    spec = setting.agent
    spec.require_text()
    agent = spec.build(num_envs)
    if not hasattr(agent, "instruct"):
        raise ValueError(f"agent {spec.kind!r} does not follow instructions (no instruct method)")
    for text in [c.instruction for c in columns] + [None]:
        agent.instruct([text] * num_envs)  # an instruction it cannot follow fails here
    played = inference_meta(agent, spec.temperature)
    spec = replace(spec, cfg_scale=played.get("cfg_scale"), temperature=played["temperature"])
    return agent, replace(setting, agent=spec)


def check_saved(out: Path, games: Sequence[str], columns: Sequence[SubTask], s: Setting) -> None:
    """Raise ValueError before anything is played if a saved row has another setting."""
    for game in games:
        for label in row_labels(columns):
            load_row(_row_path(out, game, label), s)


def _row_path(out: Path, game: str, label: str) -> Path:
    return out / game / f"{label.replace(' ', '_')}.json"


def load_row(path: Path, setting: Setting) -> list[dict[str, int]] | None:
    """A saved row's episodes, None if there is none; ValueError if another setting made it."""
    if not path.is_file():
        return None
    saved = json.loads(path.read_text())
    if saved["setting"] != setting.record():
        diff = {k: v for k, v in saved["setting"].items() if setting.record().get(k) != v}
        raise ValueError(f"{path} was played with another setting {diff}; give another --out")
    return [e["unlock_step"] for e in saved["episodes"]]


def play_row(
    agent: InstructableAgent, env: GameEnv, instruction: str | None, setting: Setting
) -> list[dict]:
    """N episodes of one row: each episode's seed and first unlock step per achievement."""
    told = _Told(agent, instruction, env.num_envs)
    results = evaluate(told, env, setting.episodes, setting.seed, record_gif_episode=None)
    return [{"seed": r.seed, "unlock_step": {ACHIEVEMENT_NAMES[i]: int(s)
                                              for i, s in enumerate(r.unlock_step) if s > 0}}
            for r in results]


def play_game(
    agent: InstructableAgent, game: str, columns: Sequence[SubTask], setting: Setting,
    out: Path, num_envs: int,
) -> tuple[dict[str, list[dict[str, int]]], dict[str, float]]:
    """Every row of one game, read if saved, else played and saved; with each played row's
    seconds."""
    rows, seconds, env = {}, {}, None
    labels = row_labels(columns)
    for k, label in enumerate(labels, 1):
        path = _row_path(out, game, label)
        rows[label] = load_row(path, setting)
        if rows[label] is not None:
            print(f"{game}: row {k}/{len(labels)} {label!r} read from {path}", flush=True)
            continue
        print(f"{game}: row {k}/{len(labels)} {label!r}", flush=True)
        if env is None:  # built once per game (Craftax compiles its step once)
            env = make_env(game, num_envs, pixels=agent.needs_pixels, max_steps=setting.max_steps)
        start = time.perf_counter()
        episodes = play_row(agent, env, None if label == NO_INSTRUCTION else label, setting)
        seconds[label] = round(time.perf_counter() - start, 1)
        path.parent.mkdir(parents=True, exist_ok=True)
        saved = {"game": game, "instruction": label, "setting": setting.record(),
                 "seconds": seconds[label], "episodes": episodes}
        atomic_write_text(path, json.dumps(saved) + "\n")  # a killed run leaves no half row
        rows[label] = [e["unlock_step"] for e in episodes]
    return rows, seconds


def run(
    agent: InstructableAgent, setting: Setting, games: Sequence[str],
    columns: Sequence[SubTask], out: Path, num_envs: int, horizons: Sequence[int] = (),
) -> dict:
    """Play (or read) every row in every game and write OUT/report.json, report.md and
    matrix.png; returns the report. Each of ``horizons`` (shorter than L, ``check_horizons``)
    scores the same episodes again, within its first steps: an agent's play does not depend
    on L, so this is the matrix a shorter --max-steps would give, without playing it."""
    report: dict = {
        "setting": setting.record(), "columns": [
            {"instruction": c.instruction, "achievement": ACHIEVEMENT_NAMES[c.achievement]}
            for c in columns],
        "rows": row_labels(columns), "games": {},
    }
    for game in games:
        rows, seconds = play_game(agent, game, columns, setting, out, num_envs)
        report["games"][game] = {
            **score(rows, columns, setting.episodes, setting.max_steps, game),
            "seconds_played": seconds,
            "horizons": {str(h): score(rows, columns, setting.episodes, h, game)
                         for h in horizons},
        }
        for h, g in [(setting.max_steps, report["games"][game]),
                     *((int(h), g) for h, g in report["games"][game]["horizons"].items())]:
            print(f"within {h} steps: {g['verdict_line']}", *versus_none(g, setting.episodes),
                  sep="\n", flush=True)
    report["written_at"] = datetime.now(UTC).isoformat(timespec="seconds")
    report["files"] = ["report.json", "report.md", "matrix.png"]
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    (out / "report.md").write_text(format_markdown(report))
    plot_matrix(report, out / "matrix.png")
    return report


def format_markdown(report: dict) -> str:
    """Per game the matrix (k/N and the Wilson 95% interval in %; bold: the row's own
    instruction, italic: the column's best other instruction, if it gets any), each column's
    own instruction against none (``versus_none``) and the verdict line."""
    s, agent = report["setting"], report["setting"]["agent"]
    who = agent["kind"] + (f" ({agent['checkpoint']})" if "checkpoint" in agent else "")
    guidance = f", guidance scale {agent['cfg_scale']:g}" if "cfg_scale" in agent else ""
    lines = [
        f"# Instruction matrix: {who}", "",
        (f"{s['episodes']} episodes per row, episode j seeded from ({s['seed']}, j) in every "
         "row; a cell counts the episodes where the column's achievement first happens within "
         f"{s['max_steps']} steps: k/N (Wilson 95%, %). Bold: the row's own instruction; italic: "
         "the column's best other instruction, if it gets any. Temperature "
         f"{agent.get('temperature', 1.0):g}{guidance}."),
    ]
    names = [c["achievement"] for c in report["columns"]]
    for game, g in report["games"].items():
        lines += ["", f"## {game}", "", *_scored(g, names, s["episodes"])]
        for h, within in g.get("horizons", {}).items():
            lines += ["", f"### {game}, the same episodes within {h} steps", "",
                      *_scored(within, names, s["episodes"])]
    return "\n".join(lines) + "\n"


def _scored(g: dict, names: list[str], episodes: int) -> list[str]:
    """One scored matrix (``score``) as markdown: the table, own against none, the verdict."""
    return [*_table(g, names, episodes), "", *versus_none(g, episodes), "", g["verdict_line"]]


def versus_none(g: dict, episodes: int) -> list[str]:
    """Per column, told against untold as markdown table lines: the counts, whether their
    Wilson 95% intervals are disjoint, and the two-proportion test's p-value (the stricter
    bar and the usual one: 38/50 vs 27/50 overlap, yet p = 0.021)."""
    lines = ["| column | told | untold | disjoint 95% intervals | two-proportion p |",
             "|---|---:|---:|---|---:|"]
    for c in g["columns"]:
        disjoint = "above" if c["separated_from_none"] else (
            "below" if c["worse_than_none"] else "no")
        lines.append(f"| {c['achievement']} | {c['own']}/{episodes} | "
                     f"{c['no_instruction']}/{episodes} | {disjoint} | "
                     f"{p_text(c['p_two_proportion_vs_none'])} |")
    return lines


def _table(g: dict, names: list[str], episodes: int) -> list[str]:
    """One scored matrix (``score``) as markdown table lines."""
    marks = {(c["instruction"], c["achievement"]): "**" for c in g["columns"]}
    marks.update({(r, c["achievement"]): "_" for c in g["columns"] for r in _marked(c)})
    lines = ["| instruction | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for row, cells in g["counts"].items():
        texts = []
        for a in names:
            low, high = g["wilson95_percent"][row][a]
            mark = marks.get((row, a), "")
            texts.append(f"{mark}{cells[a]}/{episodes} ({low:.0f}–{high:.0f}){mark}")
        lines.append(f"| {row} | " + " | ".join(texts) + " |")
    return lines


def _marked(column: dict) -> list[str]:
    """The best other instructions worth marking: none when the best gets nothing."""
    return column["best_other"] if column["best_other_count"] else []


def plot_matrix(report: dict, path: Path) -> Path:
    """A heat-map per game, side by side: share of episodes per cell, annotated k/N; the own
    instruction's cells are outlined solid red, the best other instruction's (if it gets any)
    dashed white. Drawn on an Agg canvas (as ``zoo.eval.plots``), so the caller's matplotlib
    backend is left alone."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    games, rows = list(report["games"]), report["rows"]
    names, n = [c["achievement"] for c in report["columns"]], report["setting"]["episodes"]
    fig = Figure(figsize=(1.1 * len(names) * len(games) + 2.5, 0.45 * len(rows) + 2.2), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(games), squeeze=False)[0]
    for ax, game in zip(axes, games, strict=True):
        g = report["games"][game]
        share = np.array([[g["counts"][r][a] / n for a in names] for r in rows])
        image = ax.imshow(share, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        for (i, j), value in np.ndenumerate(share):
            ax.text(j, i, f"{g['counts'][rows[i]][names[j]]}/{n}", ha="center", va="center",
                    fontsize=8, color="black" if value > 0.6 else "white")
        for j, column in enumerate(g["columns"]):
            for label, style, color, inset in [(column["instruction"], "-", "red", 0.04)] + [
                    (r, "--", "white", 0.1) for r in _marked(column)]:
                ax.add_patch(Rectangle(
                    (j - 0.5 + inset, rows.index(label) - 0.5 + inset), 1 - 2 * inset,
                    1 - 2 * inset, fill=False, edgecolor=color, linestyle=style, linewidth=2))
        ax.set_xticks(range(len(names)), [a.replace("_", " ") for a in names], rotation=35,
                      ha="right", fontsize=8)
        ax.set_yticks(range(len(rows)), rows if ax is axes[0] else [""] * len(rows), fontsize=8)
        ax.set_title(f"{game}: first within {report['setting']['max_steps']} steps", fontsize=9)
    fig.colorbar(image, ax=list(axes), label="share of episodes", fraction=0.03)
    fig.suptitle(f"{report['setting']['agent']}: own instruction solid red, best other "
                 "instruction dashed white", fontsize=9)
    fig.savefig(path, bbox_inches="tight")
    return Path(path)
