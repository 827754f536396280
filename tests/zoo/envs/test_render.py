"""The numba renderer (``zoo.envs.render``) draws Craftax-Classic's own pixels, byte for byte.

States come from random and scripted play. Copies of them are edited to show what play rarely
does: light from night through dusk to full day, sleep, every mob kind and arrow heading on,
at and just past the view's edges, the player at the map's border, every inventory digit,
vitals outside 0..9 (health below 0 at death), block ids past the last, and T1's peace (no
mobs, full vitals: what its task editor sets). Craftax's JAX renderer draws each state
(``jit(vmap)``, what ``zoo.data.rerender`` runs for the ``jax`` renderer) and the numba kernel
draws it from the exported state; every byte must agree. The default suite checks a few
hundred states, and 2,048 more at night; ``-m slow`` checks over 100k, plus the frames of the
env's own fused step+render program and of T1's task editor.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zoo.envs.render import choose_renderer, render_frames
from zoo.envs.render.noise import uniform

HEADINGS = np.array([[0, 1], [0, -1], [1, 0], [-1, 0]])
MOBS = ("zombies", "cows", "skeletons", "arrows")
JAX_BATCH = 64
NIGHT_STATES = 2048


@pytest.fixture(scope="module")
def jax_renderer():
    """Craftax's renderer and the zoo's export under one jit(vmap): (frames, exported state)."""
    import jax

    from zoo.envs.craftax_env import export_state, frame_renderer

    frame = frame_renderer()
    return jax.jit(jax.vmap(lambda s: (frame(s), export_state(s))))


def _stack(states: list):
    import jax

    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *states)


def play(env, agent, steps: int, every: int, seed: int) -> list:
    """Snapshots (numpy EnvStates, one per ``every`` steps) of ``agent`` playing ``env``."""
    import jax

    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**31, env.num_envs)
    step = env.reset(seeds)
    agent.reset(seeds)
    snapshots = []
    for t in range(steps):
        step = env.step(np.asarray(agent.act(step)))
        if t % every == 0:
            snapshots.append(jax.device_get(env.raw_state))
        if step.done.any():
            seeds = rng.integers(0, 2**31, env.num_envs)
            step = env.reset(seeds, mask=step.done)
            agent.reset(seeds, mask=step.done)
    return snapshots


def cover(s, rng: np.random.Generator):
    """Edited copies of the numpy EnvStates ``s`` (see the module docstring)."""
    n = len(s.light_level)
    pos = rng.integers(0, 64, (n, 2))
    border = rng.random(n) < 0.3
    pos[border] = rng.choice([0, 1, 2, 3, 60, 61, 62, 63], (border.sum(), 2))
    light = rng.random(n).astype(np.float32)
    fixed = rng.random(n) < 0.3
    light[fixed] = rng.choice(np.float32([0, 0.25, 0.4999, 0.5, 0.5001, 0.75, 1]), fixed.sum())
    maps = s.map.copy()
    for _ in range(8):  # random blocks (and ids past the last) on random view tiles
        r = np.clip(pos[:, 0] + rng.integers(-3, 4, n), 0, 63)
        c = np.clip(pos[:, 1] + rng.integers(-4, 5, n), 0, 63)
        maps[np.arange(n), r, c] = rng.integers(0, 18, n)
    vitals = rng.integers(0, 10, (4, n))
    odd = rng.random((4, n)) < 0.05
    vitals[odd] = rng.choice([-12, -3, -1, 10, 13], odd.sum())
    peace = rng.random(n) < 0.1  # T1: no mobs, food, drink and energy at 9
    vitals[1:, peace] = 9
    changes = {}
    for key in MOBS:
        mobs = getattr(s, key)
        slots = mobs.mask.shape[1]
        offset = np.stack([rng.integers(-4, 5, (n, slots)), rng.integers(-5, 6, (n, slots))], -1)
        changes[key] = mobs.replace(
            position=(pos[:, None] + offset).astype(mobs.position.dtype),
            mask=(rng.random((n, slots)) < 0.7) & ~peace[:, None],
        )
    directions = HEADINGS[rng.integers(0, 4, s.arrow_directions.shape[:2])]
    inv = s.inventory
    counts = {f.name: rng.integers(0, 10, n) for f in dataclasses.fields(inv)}
    for k in ("wood", "sapling", "iron_sword"):  # past 9: JAX clamps the digit's index
        counts[k][rng.random(n) < 0.05] = 12
    return s.replace(
        map=maps.astype(s.map.dtype),
        player_position=pos.astype(s.player_position.dtype),
        player_direction=rng.integers(1, 5, n).astype(s.player_direction.dtype),
        player_health=vitals[0].astype(s.player_health.dtype),
        player_food=vitals[1].astype(s.player_food.dtype),
        player_drink=vitals[2].astype(s.player_drink.dtype),
        player_energy=vitals[3].astype(s.player_energy.dtype),
        is_sleeping=rng.random(n) < 0.3,
        inventory=inv.replace(**{k: v.astype(getattr(inv, k).dtype) for k, v in counts.items()}),
        arrow_directions=directions.astype(s.arrow_directions.dtype),
        light_level=light,
        state_rng=rng.integers(0, 2**32, (n, 2), dtype=np.uint32),
        **changes,
    )


class Tally:
    """States compared, frames that differ, the largest byte difference, and what was seen."""

    def __init__(self) -> None:
        self.states = self.differing = self.max_diff = 0
        self.seen: set[str] = set()

    def add(self, ours: np.ndarray, theirs: np.ndarray, exported: dict) -> None:
        diff = np.abs(ours.astype(np.int16) - theirs.astype(np.int16)).reshape(len(ours), -1)
        self.states += len(ours)
        self.differing += int((diff.max(1) > 0).sum())
        self.max_diff = max(self.max_diff, int(diff.max()))
        self.seen |= _coverage(exported)


def _coverage(e: dict) -> set[str]:
    """Names of the cases a batch of exported states shows (``REQUIRED`` lists them all)."""
    light, seen = e["light_level"], set()
    for name, show in (("night", light < 0.5), ("dusk", (light >= 0.5) & (light < 1)),
                       ("day", light == 1), ("asleep", e["player_sleeping"]),
                       ("border", (e["player_pos"] <= 3).any(1) | (e["player_pos"] >= 60).any(1)),
                       ("peace", ~np.concatenate([e[f"{m}_status"][..., 0] != 0 for m in MOBS],
                                                 axis=1).any(1)
                        & (e["player_vitals"][:, 1:] == 9).all(1))):
        if show.any():
            seen.add(name)
    counts = np.concatenate([e["player_vitals"], e["inventory"]], axis=1)
    seen |= {f"count{k}={v}" for k in range(counts.shape[1]) for v in np.unique(counts[:, k])}
    for mob in MOBS:
        local = e[f"{mob}_pos"] - e["player_pos"][:, None] + np.array([3, 4])
        shown = e[f"{mob}_status"][..., 0] != 0
        rows, cols = local[..., 0], local[..., 1]
        inside = (rows >= 0) & (rows < 7) & (cols >= 0) & (cols < 9)
        edge = inside & ((rows == 0) | (rows == 6) | (cols == 0) | (cols == 8))
        past = ~inside & (rows >= -1) & (rows <= 7) & (cols >= -1) & (cols <= 9)
        for name, show in (("", inside), ("@edge", edge), ("@past", past)):
            if (show & shown).any():
                seen.add(mob + name)
    heading = e["arrows_dir"][e["arrows_status"][..., 0] != 0]
    seen |= {f"arrow{h.tolist()}" for h in np.unique(heading.reshape(-1, 2), axis=0)}
    return seen


REQUIRED = (
    {"night", "dusk", "day", "asleep", "border", "peace"}
    | {f"count{k}={v}" for k in range(16) for v in range(10)}
    | {m + x for m in MOBS for x in ("", "@edge", "@past")}
    | {f"arrow{h.tolist()}" for h in HEADINGS}
)


def compare(states, jax_renderer, tally: Tally) -> None:
    """Draw numpy EnvStates both ways, JAX_BATCH at a time (the tail padded), into ``tally``."""
    import jax

    n = len(states.light_level)
    for start in range(0, n, JAX_BATCH):
        take = np.minimum(np.arange(start, start + JAX_BATCH), n - 1)
        batch = jax.tree_util.tree_map(lambda x, take=take: x[take], states)
        theirs, exported = jax.device_get(jax_renderer(batch))
        ours = render_frames(exported, batch.state_rng)
        keep = slice(0, min(JAX_BATCH, n - start))
        tally.add(ours[keep], theirs[keep], {k: v[keep] for k, v in exported.items()})


def test_noise_is_jax_uniform():
    import jax

    keys = np.array([[0, 0], [1, 2], [2**32 - 1, 12345], [987654321, 4000000000]], np.uint32)
    theirs = jax.device_get(jax.vmap(lambda k: jax.random.uniform(k, (112 * 144,)))(keys))
    ours = np.empty_like(theirs)
    for key, out in zip(keys, ours):
        uniform(key[0], key[1], out)
    np.testing.assert_array_equal(ours, theirs)


def test_played_and_edited_states_render_alike(craftax_env, jax_renderer):
    from zoo.agents.base import RandomAgent
    from zoo.experts.scripted import ScriptedExpert

    rng = np.random.default_rng(0)
    played = _stack(play(craftax_env, RandomAgent(2), 120, 3, seed=1)
                    + play(craftax_env, ScriptedExpert(2), 120, 3, seed=2))
    tally = Tally()
    compare(played, jax_renderer, tally)
    for _ in range(3):
        compare(cover(played, rng), jax_renderer, tally)
    assert tally.states >= 400
    assert REQUIRED <= tally.seen, sorted(REQUIRED - tally.seen)
    assert (tally.differing, tally.max_diff) == (0, 0)


def test_thousands_of_night_states_render_alike(craftax_env, jax_renderer):
    """The night static is where the kernel's rounding is most delicate (XLA fuses its
    multiply-adds): one rounding too many there shifts a byte in ~1% of deep-night frames, so
    the ~230 night states of the test above could miss it. 2,048 edited states of 8 worlds,
    awake (sleep's grey halves the static): 3/4 in deep night (light below 0.1), where the
    static weighs most, the rest just below dusk, where its faint trace pins the threshold."""
    import jax

    rng = np.random.default_rng(3)
    worlds = []
    for seeds in (100, 101), (102, 103), (104, 105), (106, 107):
        craftax_env.reset(np.array(seeds))
        worlds.append(jax.device_get(craftax_env.raw_state))
    worlds = jax.tree_util.tree_map(lambda x: np.repeat(x, JAX_BATCH // 8, 0), _stack(worlds))
    tally = Tally()
    for _ in range(NIGHT_STATES // JAX_BATCH):
        deep = rng.random(JAX_BATCH) < 0.75
        light = np.where(deep, 0.1 * rng.random(JAX_BATCH), 0.49 + 0.01 * rng.random(JAX_BATCH))
        night = cover(worlds, rng).replace(light_level=light.astype(np.float32),
                                           is_sleeping=np.zeros(JAX_BATCH, bool))
        compare(night, jax_renderer, tally)
    assert tally.states == NIGHT_STATES and tally.seen >= {"night"} and "day" not in tally.seen
    assert (tally.differing, tally.max_diff) == (0, 0)


def test_choose_renderer(monkeypatch):
    monkeypatch.delenv("ZOO_RENDERER", raising=False)
    assert choose_renderer() == "numba"
    assert choose_renderer(on_gpu=True) == "jax"
    monkeypatch.setenv("ZOO_RENDERER", "jax")
    assert choose_renderer() == "jax"
    assert choose_renderer("numba", on_gpu=True) == "numba"
    monkeypatch.setenv("ZOO_RENDERER", "opengl")
    with pytest.raises(ValueError, match=r"ZOO_RENDERER must be one of \('numba', 'jax'\)"):
        choose_renderer()


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_over_100k_states_render_alike(jax_renderer):
    """>= 100k states; and the frames of the env's fused step+render program and of T1's task
    editor (another jitted program) against the numba kernel on the states they export."""
    import jax

    from zoo.agents.base import RandomAgent
    from zoo.envs.craftax_env import CraftaxEnv
    from zoo.envs.tasks import TASKS, TaskEnv
    from zoo.experts.scripted import ScriptedExpert

    rng = np.random.default_rng(0)
    tally = Tally()
    env = CraftaxEnv(64, pixels=False)
    for agent, seed in ((RandomAgent(64), 1), (ScriptedExpert(64), 2)):
        for chunk in range(8):
            for snapshot in play(env, agent, 100, 2, seed=10 * seed + chunk):
                compare(snapshot, jax_renderer, tally)
                compare(cover(snapshot, rng), jax_renderer, tally)
    print(f"renderers compared on {tally.states} states: {tally.differing} frames differ")
    assert tally.states >= 100_000
    assert REQUIRED <= tally.seen, sorted(REQUIRED - tally.seen)
    assert (tally.differing, tally.max_diff) == (0, 0)
    programs = Tally()
    t1_jax = TaskEnv(CraftaxEnv(8, max_steps=TASKS["T1"].max_steps, renderer="jax"), TASKS["T1"])
    for game in (CraftaxEnv(16, renderer="jax"), t1_jax):
        agent = RandomAgent(game.num_envs)
        step = game.reset(np.arange(game.num_envs))
        agent.reset(np.arange(game.num_envs))
        for _ in range(600):
            step = game.step(agent.act(step))
            rngs = jax.device_get(game.raw_state.state_rng)
            programs.add(render_frames(step.state, rngs), step.frames, step.state)
            if step.done.any():
                fresh = rng.integers(0, 2**31, game.num_envs)
                step = game.reset(fresh, mask=step.done)
                agent.reset(fresh, mask=step.done)
    print(f"env and T1 programs compared on {programs.states} frames: "
          f"{programs.differing} differ")
    assert (programs.differing, programs.max_diff) == (0, 0)


def test_render_frames_checks_shapes():
    from zoo.envs.schema import empty_state

    state = empty_state(2)
    assert render_frames(state, np.zeros((2, 2), np.uint32)).shape == (2, 144, 144, 3)
    state["cows_pos"] = np.zeros((2, 9, 2), np.int16)  # the kernel does not check bounds
    with pytest.raises(ValueError, match=r"'cows_pos' has shape \(2, 9, 2\), expected \(2, 4, 2\)"):
        render_frames(state, np.zeros((2, 2), np.uint32))
    with pytest.raises(ValueError, match=r"state_rng must be \(n, 2\)"):
        render_frames(empty_state(2), np.zeros((2, 3), np.uint32))


def test_render_frames_into_a_given_buffer():
    """Generation draws a chunk into a recycled buffer: the same frames, written in place; a
    buffer of another shape or layout is refused before the kernel (which checks no bounds)."""
    from zoo.envs.schema import empty_state

    state, rng = empty_state(2), np.array([[1, 2], [3, 4]], np.uint32)
    buffer = np.full((3, 144, 144, 3), 7, np.uint8)
    view = buffer[:2]
    assert render_frames(state, rng, out=view) is view
    np.testing.assert_array_equal(buffer[:2], render_frames(state, rng))
    assert (buffer[2] == 7).all()
    with pytest.raises(ValueError, match=r"out must be C-contiguous uint8 \(2, 144, 144, 3\)"):
        render_frames(state, rng, out=buffer)
    with pytest.raises(ValueError, match="out must be C-contiguous"):
        render_frames(state, rng, out=np.zeros((2, 144, 144, 3), np.uint8)[:, ::-1])


def test_task_editor_frames_alike_with_either_renderer():
    """T1's editor (peaceful, full vitals, a starting inventory) re-renders its edited states
    with the env's renderer: the numba kernel after the jitted edit, or JAX inside it."""
    from zoo.envs.craftax_env import CraftaxEnv
    from zoo.envs.tasks import TASKS, TaskEnv

    seeds = np.array([11, 12, 13])
    frames = {}
    for renderer in ("numba", "jax"):
        env = TaskEnv(CraftaxEnv(3, renderer=renderer), TASKS["T1"])
        step = env.reset(seeds)
        frames[renderer] = [step.frames.copy()]
        for action in (1, 5, 2, 5):
            frames[renderer].append(env.step(np.full(3, action)).frames.copy())
    assert all(np.array_equal(a, b) for a, b in zip(frames["numba"], frames["jax"]))
