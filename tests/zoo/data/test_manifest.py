"""The manifest's ``config``: DAgger settings nested, the learner as its ``AgentSpec`` record
(kind, files and sha256s), a resume that refuses other settings key by key, and version-1
manifests read as version 2 writes them."""

from __future__ import annotations

import dataclasses
import json

import pytest

from zoo.agents import dataset_agent
from zoo.data.generate import generate
from zoo.data.manifest import DatasetMismatchError, check_same_config, config_diff, load_manifest
from zoo.data.shard_generator import DaggerSettings, GenerationConfig

SHA = "df0f11587f861444bdc2f396822dd67d409ec9a1aad462430d2be1259bde797a"
COMMON = {
    "checkpoint": None, "chunk_length": 256, "env": "crafter", "episodes": 1,
    "episodes_per_shard": 16, "expert_options": None, "frames": None, "max_steps": 20,
    "min_noop_run": 20, "seed": 3, "zstd_level": 2, "zstd_window_log": 25,
}
LEARNER = {"kind": "cvpt", "checkpoint": "/data/learner", "checkpoint_sha256": SHA,
           "temperature": 1.0}
DAGGER = GenerationConfig(
    expert="scripted", episodes=1, seed=3, env="crafter", max_steps=20,
    dagger=DaggerSettings(learner=LEARNER, beta=0.25, mix="step", round=2),
)
EXPERT = GenerationConfig(expert="random", episodes=1, seed=3, env="crafter", max_steps=20)


def _read_back(tmp_path, config: dict, version: int = 2) -> dict:
    """``config`` written into a manifest and read back by ``load_manifest``."""
    manifest = {"format": "crafterplay", "format_version": version, "config": config,
                "shards": []}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    return load_manifest(tmp_path)


def test_an_expert_config_has_no_dagger_fields_and_a_dagger_config_nests_them() -> None:
    stored = dataclasses.asdict(EXPERT)
    assert stored["dagger"] is None
    assert not {"source", "learner", "beta", "mix", "round"} & set(stored)
    assert dataclasses.asdict(DAGGER)["dagger"]["beta"] == 0.25
    assert dataclasses.asdict(DAGGER)["dagger"]["learner"] == LEARNER
    assert GenerationConfig(**dataclasses.asdict(DAGGER)) == DAGGER  # as merge reads it back
    assert hash(DAGGER) == hash(dataclasses.replace(DAGGER))


@pytest.mark.parametrize("config", [DAGGER, EXPERT])
def test_a_manifest_reads_back_as_the_config_it_was_written_from(tmp_path, config) -> None:
    manifest = _read_back(tmp_path, dataclasses.asdict(config))
    assert GenerationConfig(**manifest["config"]) == config
    check_same_config(manifest, dataclasses.asdict(config), tmp_path)  # resumes: no error


def test_a_dagger_manifest_refuses_other_settings_other_weights_and_expert_play(tmp_path) -> None:
    manifest = _read_back(tmp_path, dataclasses.asdict(DAGGER))
    other = dataclasses.replace(DAGGER, dagger=dataclasses.replace(DAGGER.dagger, beta=0.5))
    with pytest.raises(DatasetMismatchError, match=r"\(dagger.beta: 0.25 there vs 0.5 now\)"):
        check_same_config(manifest, dataclasses.asdict(other), tmp_path)
    retrained = dataclasses.replace(DAGGER, dagger=dataclasses.replace(
        DAGGER.dagger, learner={**LEARNER, "checkpoint_sha256": "0" * 64}))
    with pytest.raises(DatasetMismatchError, match="dagger.learner"):
        check_same_config(manifest, dataclasses.asdict(retrained), tmp_path)
    expert = dataclasses.replace(DAGGER, dagger=None)
    with pytest.raises(DatasetMismatchError, match=r"dagger: \{.*'round': 2\} there vs None now"):
        check_same_config(manifest, dataclasses.asdict(expert), tmp_path)


def test_a_version_1_manifest_reads_with_this_versions_spellings(tmp_path) -> None:
    """Version 1 wrote the defaults of frames, start_states and expert_options as null and
    predates the dagger, instructions and start_states fields: it resumes as the same data."""
    manifest = _read_back(tmp_path, {**COMMON, "expert": "random"}, version=1)
    assert manifest["format_version"] == 2
    assert manifest["config"]["frames"] == "stored"
    assert manifest["config"]["start_states"] == "default"
    assert manifest["config"]["expert_options"] == {}
    assert config_diff(manifest["config"], dataclasses.asdict(EXPERT)) == ""
    check_same_config(manifest, dataclasses.asdict(EXPERT), tmp_path)  # resumes: no error


def test_a_version_1_folder_resumes_to_the_same_shards_and_is_saved_as_version_2(tmp_path):
    """A half-written folder of version 1 (its first shard, its config in version 1's nulls and
    without the later fields) is finished by a rerun: the same bytes as one uninterrupted run."""
    config = dataclasses.replace(EXPERT, episodes=2, episodes_per_shard=1)
    whole, part = tmp_path / "whole", tmp_path / "part"
    generate(config, whole, progress=False, build_agent=dataset_agent)
    generate(config, part, progress=False, build_agent=dataset_agent, shards=(0, 1))
    manifest = json.loads((part / "manifest.json").read_text())
    manifest["format_version"] = 1
    for key in ("frames", "expert_options"):
        manifest["config"][key] = None
    for key in ("dagger", "instructions", "start_states"):
        del manifest["config"][key]
    (part / "manifest.json").write_text(json.dumps(manifest))
    generate(config, part, progress=False, build_agent=dataset_agent)
    saved = json.loads((part / "manifest.json").read_text())
    assert saved["format_version"] == 2 and saved["config"] == dataclasses.asdict(config)
    assert [e["sha256"] for e in saved["shards"]] == [
        e["sha256"] for e in load_manifest(whole)["shards"]]


def test_a_manifest_of_an_unknown_version_is_refused_by_name(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"manifest.json: CrafterPlay format version 3, this "
                                         r"zoo reads versions 1 and 2"):
        _read_back(tmp_path, dataclasses.asdict(EXPERT), version=3)


def test_the_defaults_have_one_spelling() -> None:
    stored = dataclasses.asdict(EXPERT)
    assert (stored["frames"], stored["start_states"], stored["expert_options"]) == (
        "stored", "default", {})
    with pytest.raises(ValueError, match="frames must be 'stored' or 'rendered', got None"):
        GenerationConfig(expert="random", episodes=1, seed=3, frames=None)


def test_dagger_settings_need_a_learner_record() -> None:
    with pytest.raises(ValueError, match="learner is an AgentSpec record with kind, checkpoint"):
        DaggerSettings(learner={"kind": "cvpt", "checkpoint": "x"}, beta=0.0, mix="step")
    with pytest.raises(ValueError, match="AgentSpec record"):
        GenerationConfig(**{**dataclasses.asdict(DAGGER), "dagger": {
            "learner": "/data/learner", "beta": 0.25, "mix": "step"}})
