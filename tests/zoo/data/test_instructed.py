"""Goal-directed generation (``--instructions``, ``--start-states tasks``): deterministic bytes,
the recorded instruction is the one the expert pursued and switches on completion or timeout,
the manifest records the schedule and a resume refuses another, old shards still read."""

from __future__ import annotations

import dataclasses
import json
import shutil
import tarfile
from itertools import pairwise
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from zoo.agents import dataset_agent
from zoo.agents.instructions import instruction_schedule
from zoo.cli import main
from zoo.data.codec import decode_arrays
from zoo.data.generate import GenerationConfig, ShardGenerator, generate
from zoo.data.manifest import DatasetMismatchError, load_manifest
from zoo.data.reader import NO_INSTRUCTION, iter_chunks, iter_episodes, list_shards
from zoo.data.shard_generator import DaggerSettings
from zoo.data.shards import STEPS
from zoo.envs import make_env
from zoo.envs.tasks.starts import TaskStartEnv, start_index, task_starts
from zoo.experts.scripted import ScriptedExpert
from zoo.experts.scripted.schedule import COMPLETED_BY, OUTCOMES, instruction_events

TIMEOUT = 25
SCHEDULE = instruction_schedule("captions", TIMEOUT)
# 3 episodes in shard 0 on 2 envs: one env idles while the other plays the third episode
INSTRUCTED = GenerationConfig(
    expert="scripted", episodes=4, seed=6, env="crafter", episodes_per_shard=3, chunk_length=32,
    max_steps=120, instructions=SCHEDULE, start_states="tasks",
)
COMMAND = [
    "data", "generate", "--expert", "scripted", "--episodes", "4", "--seed", "6", "--env",
    "crafter", "--episodes-per-shard", "3", "--chunk-length", "32", "--max-steps", "120",
    "--instructions", "captions", "--instruction-timeout", str(TIMEOUT), "--start-states", "tasks",
    "--no-progress",
]
TEXT = dict(zip(SCHEDULE.caption_ids, SCHEDULE.captions))


class PursuitLog(ScriptedExpert):
    """The scripted expert, noting before every action what each env was told to pursue."""

    log: ClassVar[list[list[str | None]]] = []

    def act(self, step):
        self.log.append([planner.instruction for planner in self._planners])
        return super().act(step)


def _shas(root: Path) -> list[str]:
    return [e["sha256"] for e in load_manifest(root)["shards"]]


def _episodes(root: Path) -> list[dict]:
    return list(iter_episodes(list_shards(root)))


@pytest.fixture(scope="module")
def instructed(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("instructed")
    generate(INSTRUCTED, root, num_envs=2, progress=False, build_agent=dataset_agent)
    return root


def test_the_same_command_gives_the_same_bytes_for_any_num_envs(instructed, tmp_path) -> None:
    assert main([*COMMAND, "--num-envs", "1", "--out", str(tmp_path)]) == 0
    assert _shas(tmp_path) == _shas(instructed)
    assert load_manifest(tmp_path) == load_manifest(instructed)


def test_each_step_records_the_instruction_the_expert_pursued(instructed, tmp_path) -> None:
    PursuitLog.log = []
    generator = ShardGenerator(INSTRUCTED, 1, lambda config, n: PursuitLog(n))
    generate(INSTRUCTED, tmp_path, progress=False, generator=generator)
    assert _shas(tmp_path) == _shas(instructed)
    recorded = np.concatenate([e["instruction"][:-1] for e in _episodes(tmp_path)])
    assert [TEXT[i] for i in recorded.tolist()] == [told[0] for told in PursuitLog.log]


def test_instructions_switch_when_completed_or_timed_out(instructed) -> None:
    outcomes = set()
    for episode in _episodes(instructed):
        actions = len(episode["actions"]) - 1  # the final observation has no action
        segments = episode["meta"]["instructions"]
        expanded = np.full(actions + 1, NO_INSTRUCTION)
        for start, stop, caption_id, _ in segments:
            expanded[start:stop] = caption_id
        np.testing.assert_array_equal(episode["instruction"], expanded)
        assert segments[0][0] == 0 and all(a[1] <= b[0] for a, b in pairwise(segments))
        state = episode["state"]
        events = instruction_events(
            {k: v[:-1] for k, v in state.items()}, {k: v[1:] for k, v in state.items()}
        )
        for start, stop, caption_id, outcome in segments:
            hits = events[start:stop, COMPLETED_BY[TEXT[caption_id]]]
            outcomes.add(outcome)
            assert not hits[:-1].any(), "an instruction outlived its completion"
            if outcome == "completed":
                assert hits[-1]
            elif outcome == "timed_out":
                assert not hits[-1] and stop - start == TIMEOUT
            elif outcome == "interrupted":  # night fell, or the player is tired: a rest
                energy, light = state["player_vitals"][stop, 3], state["light_level"][stop]
                assert not hits[-1] and (light < 0.45 or energy <= 3)
            else:
                assert outcome == "ended" and stop == actions and not hits[-1]
        assert segments[-1][1] == actions or episode["instruction"][-2] == NO_INSTRUCTION
    assert {"completed", "timed_out", "ended"} <= outcomes


def test_the_manifest_records_the_schedule_and_how_instructions_ended(instructed, capsys) -> None:
    manifest = load_manifest(instructed)
    assert GenerationConfig(**manifest["config"]) == INSTRUCTED
    assert manifest["config"]["instructions"]["caption_ids"] == list(SCHEDULE.caption_ids)
    given = sum(len(e["meta"]["instructions"]) for e in _episodes(instructed))
    tallies = [row for entry in manifest["shards"] for row in entry["instructions"].values()]
    assert sum(r[outcome] for r in tallies for outcome in OUTCOMES) == given
    assert main(["data", "info", str(instructed)]) == 0
    assert f"instructions (timeout {TIMEOUT} actions)" in capsys.readouterr().out


def test_a_resume_refuses_another_schedule_and_accepts_the_same(instructed, tmp_path) -> None:
    root = tmp_path / "copy"
    shutil.copytree(instructed, root)
    longer = dataclasses.replace(SCHEDULE, timeout=TIMEOUT + 5)
    with pytest.raises(DatasetMismatchError, match=r"instructions.timeout: 25 there vs 30 now"):
        generate(dataclasses.replace(INSTRUCTED, instructions=longer), root, progress=False,
                 build_agent=dataset_agent)
    with pytest.raises(DatasetMismatchError, match=r"instructions: \{.*\} there vs None now"):
        generate(dataclasses.replace(INSTRUCTED, instructions=None), root, progress=False,
                 build_agent=dataset_agent)
    with pytest.raises(DatasetMismatchError, match="start_states: 'tasks' there vs 'default' now"):
        generate(dataclasses.replace(INSTRUCTED, start_states="default"), root, progress=False,
                 build_agent=dataset_agent)
    generate(INSTRUCTED, root, progress=False, build_agent=dataset_agent)  # resumes: all done
    assert _shas(root) == _shas(instructed)


def test_episodes_start_from_the_task_suites_inventories(instructed) -> None:
    starts = task_starts()
    seen = set()
    for episode in _episodes(instructed):
        k = start_index(episode["meta"]["seed"], len(starts))
        seen.add(k)
        np.testing.assert_array_equal(
            episode["state"]["inventory"][0], starts[k].inventory_vector()
        )
    assert seen == {0, 1, 2}


def test_shards_without_instructions_keep_their_format_and_read_as_none(tmp_path) -> None:
    config = dataclasses.replace(INSTRUCTED, expert="random", instructions=None, episodes=1)
    generate(config, tmp_path, progress=False, build_agent=dataset_agent)
    with tarfile.open(list_shards(tmp_path)[0]) as tar:
        member = next(m for m in tar.getmembers() if m.name.endswith(STEPS))
        stored = decode_arrays(tar.extractfile(member).read(), "steps")
    assert set(stored) == {"actions", "rewards", "noop", "noop_run"}
    for chunk in iter_chunks(list_shards(tmp_path)):
        assert chunk["instruction"].dtype == np.int16 and (chunk["instruction"] == -1).all()
        assert "instructions" not in chunk["meta"]
    assert (_episodes(tmp_path)[0]["instruction"] == NO_INSTRUCTION).all()


def test_a_schedule_needs_the_scripted_expert() -> None:
    with pytest.raises(ValueError, match="followed by the scripted expert"):
        dataclasses.replace(INSTRUCTED, expert="random")
    dagger = DaggerSettings({"kind": "cvpt", "checkpoint": "learner", "checkpoint_sha256": "sha"},
                            0.0, "episode")
    assert dataclasses.replace(INSTRUCTED, dagger=dagger).dagger == dagger  # goal-directed DAgger
    with pytest.raises(ValueError, match="start_states must be one of"):
        dataclasses.replace(INSTRUCTED, start_states="anywhere")
    assert dataclasses.replace(INSTRUCTED, start_states="default").start_states == "default"
    stored = json.loads(json.dumps(dataclasses.asdict(INSTRUCTED)))
    assert GenerationConfig(**stored) == INSTRUCTED and hash(GenerationConfig(**stored))


@pytest.mark.parametrize("extra, message", [
    (["--expert", "random"], "--instructions needs --expert scripted, not random"),
    (["--instructions", "no-such-file.txt"], "expected captions or subgoals or a file"),
])
def test_bad_instruction_arguments_give_clear_errors(tmp_path, capsys, extra, message) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([*COMMAND, "--out", str(tmp_path / "new"), *extra])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err



CRAFTAX = dataclasses.replace(INSTRUCTED, env="craftax", episodes=2, max_steps=30, chunk_length=16)


@pytest.fixture(scope="module")
def craftax_stored(tmp_path_factory) -> tuple[Path, ShardGenerator]:
    root = tmp_path_factory.mktemp("instructed_craftax")
    generator = ShardGenerator(CRAFTAX, 2, dataset_agent)
    generate(CRAFTAX, root, progress=False, generator=generator)
    return root, generator


def test_craftax_starts_are_edited_in_the_game_and_replay_bit_exact(craftax_stored) -> None:
    """The start's edit reaches Craftax's own state: a replay from the seed (with the same
    edit, in an env that draws its frames: the scripted expert's env drew none, its frames
    were drawn from the states) gives the stored frames and states."""
    root, _ = craftax_stored
    replay = TaskStartEnv(make_env("craftax", 2, pixels=True, max_steps=CRAFTAX.max_steps))
    starts = task_starts()
    for episode in _episodes(root):
        seed = episode["meta"]["seed"]
        start = starts[start_index(seed, len(starts))].inventory_vector()
        assert start.any() and (episode["state"]["inventory"][0] == start).all()
        step = replay.reset(np.array([seed, seed]))
        for t, action in enumerate(episode["actions"]):
            np.testing.assert_array_equal(step.frames[0], episode["frames"][t])
            for name, stored in episode["state"].items():
                np.testing.assert_array_equal(step.state[name][0], stored[t], name)
            if action < 0:
                break
            step = replay.step(np.array([action, action]))


@pytest.mark.slow
def test_craftax_rendered_frames_of_edited_starts_equal_the_stored(craftax_stored) -> None:
    root = craftax_stored[0]
    rendered = root.parent / "rendered"
    generate(dataclasses.replace(CRAFTAX, frames="rendered"), rendered, progress=False,
             build_agent=dataset_agent)
    for a, b in zip(_episodes(root), _episodes(rendered), strict=True):
        np.testing.assert_array_equal(a["frames"], b["frames"])
