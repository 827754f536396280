"""The manifest's ``config``: DAgger settings nested, and manifests written before that (flat
DAgger fields beside ``source``) read back in the nested form, so old folders still resume."""

from __future__ import annotations

import dataclasses
import json

import pytest

from zoo.data.manifest import (
    FLAT_DAGGER_KEYS,
    LATER_DAGGER_KEYS,
    DatasetMismatchError,
    check_same_config,
    config_diff,
    load_manifest,
    nest_dagger,
)
from zoo.data.shard_generator import DaggerSettings, GenerationConfig

SHA = "df0f11587f861444bdc2f396822dd67d409ec9a1aad462430d2be1259bde797a"
COMMON = {
    "checkpoint": None, "chunk_length": 256, "env": "crafter", "episodes": 1,
    "episodes_per_shard": 16, "expert_options": None, "frames": None, "max_steps": 20,
    "min_noop_run": 20, "seed": 3, "zstd_level": 2, "zstd_window_log": 25,
}
# ``config`` as `zoo data dagger` / `zoo data generate` wrote it before GenerationConfig.dagger
# (commit b01adda), copied from the manifests that code wrote
OLD_DAGGER = {
    **COMMON, "expert": "scripted", "source": "dagger", "learner": "/data/learner",
    "learner_sha256": SHA, "learner_temperature": 1.0, "beta": 0.25, "mix": "step", "round": 2,
}
OLD_EXPERT = {
    **COMMON, "expert": "random", "source": None, "learner": None, "learner_sha256": None,
    "learner_temperature": None, "beta": None, "mix": None, "round": None,
}
DAGGER = GenerationConfig(
    expert="scripted", episodes=1, seed=3, env="crafter", max_steps=20,
    dagger=DaggerSettings(learner="/data/learner", learner_sha256=SHA, learner_temperature=1.0,
                          beta=0.25, mix="step", round=2),
)
EXPERT = GenerationConfig(expert="random", episodes=1, seed=3, env="crafter", max_steps=20)


def _read_back(tmp_path, config: dict) -> dict:
    """``config`` written into a manifest and read back by ``load_manifest``."""
    manifest = {"format": "crafterplay", "format_version": 1, "config": config, "shards": []}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    return load_manifest(tmp_path)


def test_an_expert_config_has_no_dagger_fields_and_a_dagger_config_nests_them() -> None:
    stored = dataclasses.asdict(EXPERT)
    assert stored["dagger"] is None
    assert not {"source", "learner", "beta", "mix", "round"} & set(stored)
    assert dataclasses.asdict(DAGGER)["dagger"]["beta"] == 0.25
    assert GenerationConfig(**dataclasses.asdict(DAGGER)) == DAGGER  # as merge reads it back


@pytest.mark.parametrize("old, new", [(OLD_DAGGER, DAGGER), (OLD_EXPERT, EXPERT)])
def test_an_old_flat_manifest_reads_as_the_nested_config(tmp_path, old, new) -> None:
    manifest = _read_back(tmp_path, old)
    assert manifest["config"] == dataclasses.asdict(new)
    assert GenerationConfig(**manifest["config"]) == new
    check_same_config(manifest, dataclasses.asdict(new), tmp_path)  # resumes: no error


def test_an_old_dagger_manifest_refuses_other_settings_and_expert_play(tmp_path) -> None:
    manifest = _read_back(tmp_path, OLD_DAGGER)
    other = dataclasses.replace(DAGGER, dagger=dataclasses.replace(DAGGER.dagger, beta=0.5))
    with pytest.raises(DatasetMismatchError, match=r"\(dagger.beta: 0.25 there vs 0.5 now\)"):
        check_same_config(manifest, dataclasses.asdict(other), tmp_path)
    expert = dataclasses.replace(DAGGER, dagger=None)
    with pytest.raises(DatasetMismatchError, match=r"dagger: \{.*'round': 2, .*\} there vs None now"):
        check_same_config(manifest, dataclasses.asdict(expert), tmp_path)


def test_the_nested_form_has_every_dagger_setting() -> None:
    keys = (*FLAT_DAGGER_KEYS, *LATER_DAGGER_KEYS)
    assert sorted(keys) == sorted(f.name for f in dataclasses.fields(DaggerSettings))


def test_a_manifest_from_before_dagger_compares_equal(tmp_path) -> None:
    manifest = _read_back(tmp_path, {**COMMON, "expert": "random"})
    assert config_diff(manifest["config"], dataclasses.asdict(EXPERT)) == ""


def test_dagger_settings_need_the_learner_and_the_mixture() -> None:
    with pytest.raises(ValueError, match="a DAgger dataset needs learner, learner_sha256"):
        GenerationConfig(**nest_dagger({**OLD_DAGGER, "learner_sha256": None}))
    with pytest.raises(TypeError, match="learner_sha256"):
        GenerationConfig(**{**dataclasses.asdict(DAGGER), "dagger": {"learner": "x"}})
