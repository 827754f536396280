"""The examples run (cleanrl's subprocess smoke tests, with tiny step counts): ppo_gym.py on crafter
with and without every wrapper; sb3_ppo.py (Craftax-Classic's single-env programs) is slow."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def run(script: str, *argv: str) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, str(EXAMPLES / script), *argv], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


@pytest.mark.parametrize("wrappers", [[], ["--cclip", "obtain sapling", "--cvpt",
                                           "--goal", "obtain sapling"]])
def test_ppo_gym_trains(wrappers):
    out = run("ppo_gym.py", "--env-id", "CrafterDojo/Crafter-collect_sapling-v0", "--num-envs",
              "2", "--num-steps", "16", "--total-steps", "64", *wrappers)
    assert out.splitlines()[-1].startswith("steps 64 |")


@pytest.mark.slow
def test_sb3_ppo_writes_its_result(tmp_path):
    run("sb3_ppo.py", "--env-id", "CrafterDojo/Craftax-make_wood_pickaxe-v0", "--steps", "256",
        "--num-envs", "1", "--eval-episodes", "2", "--out", str(tmp_path))
    result = json.loads((tmp_path / "result.json").read_text())
    assert set(result) >= {"ppo", "random"} and result["ppo"]["episodes"] == 2
