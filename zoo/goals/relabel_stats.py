"""What each relabelling mode teaches: how many steps each caption's goal labels, and from how
far ahead, over a ``zoo goals embed`` folder (its per-step captions; no model, no frames).

The C-Steve-1 tables in docs/results/csteve1.md trace a failed task back to the relabelling rule
("craft stone pickaxe" never labels a step before the table is placed); this measures that
directly, for every mode of ``zoo.goals.relabel``, so a new rule can be checked before a
23-minute training run:

    zoo goals relabel-stats --embeddings data/embed_scripted_early2k --shards 24 \\
        --out runs/relabel_stats.json

Printed per mode and caption: steps labelled with that caption's goal (share of all steps),
mean steps ahead, and the share of those steps whose piece also holds another achievement
event before the goal (the run-up, e.g. placing the table before the pickaxe).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from zoo.captions.vocabulary import load_vocabulary
from zoo.goals.embed import load_embedding_manifest, read_embedding_shard
from zoo.goals.relabel import NO_CAPTION, RELABEL_MODES, RelabelParams, episode_rng, relabel_episode

CAPTIONS = (
    "obtain sapling",
    "obtain drink",
    "place table on grass",
    "craft wood pickaxe",
    "craft wood sword",
    "craft stone pickaxe",
    "craft stone sword",
)


def mode_stats(episodes: dict[int, np.ndarray], mode: str) -> dict:
    """Per caption of CAPTIONS: steps labelled with its goal, mean steps ahead, and the share
    whose piece holds another achievement event before the goal (episodes: episode -> per-step
    caption ids, -1 for none; relabelled as training does, without unconditional pieces)."""
    params = RelabelParams(mode=mode, uncond_prob=0.0)  # type: ignore[arg-type]
    vocab = load_vocabulary()
    achievement = np.array([c.category == "achievement" for c in vocab.captions])
    ids = {text: vocab[text].id for text in CAPTIONS}
    steps = {text: 0 for text in CAPTIONS}
    ahead = {text: 0 for text in CAPTIONS}
    run_up = {text: 0 for text in CAPTIONS}
    total = achievement_steps = 0
    for episode, captions in episodes.items():
        goal_step = relabel_episode(captions, params, episode_rng(0, 0, episode)).goal_step
        goal_caption = captions[goal_step]
        total += len(captions)
        has_goal = goal_caption != NO_CAPTION
        achievement_steps += int(achievement[goal_caption[has_goal]].sum())
        for text, caption in ids.items():
            for t in np.flatnonzero(goal_caption == caption):
                steps[text] += 1
                ahead[text] += int(goal_step[t] - t)
                between = captions[t : goal_step[t]]
                between = between[(between != NO_CAPTION) & (between != caption)]
                run_up[text] += bool(achievement[between].any())
    return {
        "steps": total,
        "achievement_goal_share": achievement_steps / max(total, 1),
        "captions": {
            text: {
                "steps": steps[text],
                "share": steps[text] / max(total, 1),
                "mean_ahead": ahead[text] / max(steps[text], 1),
                "run_up_share": run_up[text] / max(steps[text], 1),
            }
            for text in CAPTIONS
        },
    }


def print_relabel_stats(embeddings: str | Path, shards: int, out: Path | None = None) -> dict:
    """Read the first ``shards`` shards of a ``zoo goals embed`` folder, print each relabelling
    mode's table, write the numbers to ``out`` (JSON) when given; returns them."""
    manifest = load_embedding_manifest(embeddings)
    episodes = {}
    for entry in manifest["shards"][:shards]:
        shard = read_embedding_shard(Path(embeddings) / entry["file"])
        episodes |= {episode: rec["caption"].astype(np.int64) for episode, rec in shard.items()}
    result = {mode: mode_stats(episodes, mode) for mode in RELABEL_MODES}
    print(f"{len(episodes)} episodes")
    for mode, stats in result.items():
        share = stats["achievement_goal_share"]
        print(f"\n{mode}: {100 * share:.1f}% of steps have an achievement caption's goal")
        print("| caption | steps labelled | share | mean steps ahead | with run-up |")
        print("|---|---:|---:|---:|---:|")
        for text, row in stats["captions"].items():
            print(
                f"| {text} | {row['steps']} | {100 * row['share']:.2f}% | "
                f"{row['mean_ahead']:.1f} | {100 * row['run_up_share']:.0f}% |"
            )
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"episodes": len(episodes), **result}, indent=2))
    return result
