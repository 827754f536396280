"""PPO on CrafterDojo in one file, cleanrl-style, using only Gymnasium's API and zoo.gym's wrappers.

The env is ``gymnasium.make_vec`` of a registered id (the native batched Craftax-Classic, or
crafter in worker processes); ``--cclip TEXT`` adds C-CLIP's dense reward, ``--cvpt`` swaps the
frames for the frozen C-VPT's features and ``--goal TEXT`` adds C-Steve-1's goal embedding.
Gymnasium's default next-step autoreset means the step after an episode's end returns the new
episode's first observation and ignores its action: that transition is masked out of the loss,
and the ending step does not bootstrap (cleanrl's convention for both end signals).

    python examples/ppo_gym.py --env-id CrafterDojo/Craftax-collect_sapling-v0 --total-steps 50000
    python examples/ppo_gym.py --env-id CrafterDojo/Craftax-collect_drink-v0 --cclip "obtain drink"
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, fields

import gymnasium
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

import zoo.gym  # noqa: F401  (registers the CrafterDojo ids)
from zoo.gym.wrappers import VectorCClipReward, VectorCVPTFeatures, VectorInstructionGoal


@dataclass
class Args:
    env_id: str = "CrafterDojo/Craftax-collect_sapling-v0"
    """a registered id (``zoo.gym.ENV_IDS``)"""
    num_envs: int = 16
    """envs stepped together"""
    total_steps: int = 50_000
    """env steps to train for"""
    num_steps: int = 128
    """steps per env per rollout"""
    seed: int = 0
    """run seed: env i starts with episode i of ``zoo eval --seed`` (and torch's seed)"""
    cclip: str | None = None
    """add ``VectorCClipReward`` for this instruction"""
    cvpt: bool = False
    """observe the frozen C-VPT's features (``VectorCVPTFeatures``) instead of frames"""
    goal: str | None = None
    """add C-Steve-1's goal embedding of this instruction (``VectorInstructionGoal``)"""
    lr: float = 2.5e-4
    """Adam learning rate"""
    gamma: float = 0.99
    """discount"""
    gae_lambda: float = 0.95
    """GAE's lambda"""
    epochs: int = 4
    """passes over each rollout"""
    minibatches: int = 4
    """minibatches per pass"""
    clip: float = 0.2
    """PPO's ratio clip"""
    ent_coef: float = 0.01
    """entropy bonus"""
    vf_coef: float = 0.5
    """value loss weight"""


def parse_args() -> Args:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    types = {"int": int, "float": float, "str": str, "str | None": str}
    for f in fields(Args):
        flag = f"--{f.name.replace('_', '-')}"
        if f.type == "bool":
            parser.add_argument(flag, action="store_true")
        else:
            parser.add_argument(flag, type=types[f.type], default=f.default)
    return Args(**vars(parser.parse_args()))


def make_envs(args: Args) -> gymnasium.vector.VectorEnv:
    models_read_frames = args.cclip is not None or args.cvpt
    envs = gymnasium.make_vec(args.env_id, num_envs=args.num_envs,
                              size=144 if models_read_frames else 72)
    if args.cclip is not None:
        envs = VectorCClipReward(envs, args.cclip)
    if args.cvpt:
        envs = VectorCVPTFeatures(envs)
    if args.goal is not None:
        envs = VectorInstructionGoal(envs, args.goal)
    return gymnasium.wrappers.vector.RecordEpisodeStatistics(envs)


class Encoder(nn.Module):
    """Frames (B, H, W, 3) uint8 -> 256 features (144 px are average-pooled to 72 first), or
    a feature vector through one layer."""

    def __init__(self, space: gymnasium.spaces.Box) -> None:
        super().__init__()
        self.pixels = len(space.shape) == 3
        if self.pixels:
            pool = [nn.AvgPool2d(2)] if space.shape[0] == 144 else []
            self.net = nn.Sequential(
                *pool, nn.Conv2d(3, 32, 8, stride=4), nn.ReLU(), nn.Conv2d(32, 64, 4, stride=2),
                nn.ReLU(), nn.Conv2d(64, 64, 3, stride=1), nn.ReLU(), nn.Flatten(),
                nn.LazyLinear(256), nn.ReLU(),
            )
        else:
            self.net = nn.Sequential(nn.Linear(space.shape[0], 256), nn.ReLU())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.pixels:
            x = x.permute(0, 3, 1, 2).float() / 255.0
        return self.net(x)


class Agent(nn.Module):
    def __init__(self, space: gymnasium.Space, num_actions: int) -> None:
        super().__init__()
        parts = space.spaces if isinstance(space, gymnasium.spaces.Dict) else {"obs": space}
        self.goal_dim = parts["goal"].shape[0] if "goal" in parts else 0
        main = next(s for k, s in parts.items() if k != "goal")
        self.key = next(k for k in parts if k != "goal")
        self.encoder = Encoder(main)
        self.actor = nn.Linear(256 + self.goal_dim, num_actions)
        self.critic = nn.Linear(256 + self.goal_dim, 1)

    def hidden(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        h = self.encoder(obs[self.key])
        return torch.cat([h, obs["goal"]], dim=1) if self.goal_dim else h

    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        return self.critic(self.hidden(obs)).squeeze(-1)

    def act(self, obs: dict[str, torch.Tensor], action: torch.Tensor | None = None):
        h = self.hidden(obs)
        dist = Categorical(logits=self.actor(h))
        action = dist.sample() if action is None else action
        return action, dist.log_prob(action), dist.entropy(), self.critic(h).squeeze(-1)


def as_dict(obs, key: str) -> dict[str, torch.Tensor]:
    obs = obs if isinstance(obs, dict) else {key: obs}
    return {k: torch.as_tensor(np.asarray(v)) for k, v in obs.items()}


def main() -> None:
    args = parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    envs = make_envs(args)
    agent = Agent(envs.single_observation_space, int(envs.single_action_space.n))
    n, steps = args.num_envs, args.num_steps
    next_obs = as_dict(envs.reset(seed=args.seed)[0], agent.key)
    agent.value(next_obs)  # materialize the lazy layer before the optimizer sees it
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
    ended = torch.zeros(n, dtype=torch.bool)  # the last step ended these envs' episodes
    buffers = {k: torch.zeros(steps, n) for k in ("logp", "reward", "done", "value", "valid")}
    actions = torch.zeros(steps, n, dtype=torch.long)
    obs_buffer: list[dict[str, torch.Tensor]] = []
    returns, successes, start = [], [], time.perf_counter()

    for update in range(args.total_steps // (n * steps)):
        obs_buffer.clear()
        for t in range(steps):
            obs_buffer.append(next_obs)
            buffers["valid"][t] = (~ended).float()  # else: an autoreset step, action ignored
            with torch.no_grad():
                action, logp, _, value = agent.act(next_obs)
            obs, reward, terminated, truncated, info = envs.step(action.numpy())
            ended = torch.as_tensor(terminated | truncated)
            actions[t], buffers["logp"][t], buffers["value"][t] = action, logp, value
            buffers["reward"][t] = torch.as_tensor(reward, dtype=torch.float32)
            buffers["done"][t] = ended.float()
            next_obs = as_dict(obs, agent.key)
            if "episode" in info:
                finished = info["_episode"]
                returns += info["episode"]["r"][finished].tolist()
                successes += np.asarray(info["success"])[finished].tolist() if "success" in info else []

        with torch.no_grad():  # GAE; an ending step does not bootstrap
            advantages = torch.zeros(steps, n)
            last, next_value = torch.zeros(n), agent.value(next_obs)
            for t in reversed(range(steps)):
                keep = 1.0 - buffers["done"][t]
                nv = next_value if t == steps - 1 else buffers["value"][t + 1]
                delta = buffers["reward"][t] + args.gamma * nv * keep - buffers["value"][t]
                last = delta + args.gamma * args.gae_lambda * keep * last
                advantages[t] = last
            targets = advantages + buffers["value"]

        flat_obs = {k: torch.cat([o[k] for o in obs_buffer]) for k in obs_buffer[0]}
        flat = {k: v.reshape(-1) for k, v in buffers.items()}
        flat_adv, flat_targets, flat_actions = advantages.reshape(-1), targets.reshape(-1), actions.reshape(-1)
        for _ in range(args.epochs):
            for idx in torch.randperm(n * steps).chunk(args.minibatches):
                mask = flat["valid"][idx]
                _, logp, entropy, value = agent.act({k: v[idx] for k, v in flat_obs.items()},
                                                    flat_actions[idx])
                adv = flat_adv[idx]
                adv = (adv - adv[mask > 0].mean()) / (adv[mask > 0].std() + 1e-8)
                ratio = (logp - flat["logp"][idx]).exp()
                pg = torch.max(-adv * ratio, -adv * ratio.clamp(1 - args.clip, 1 + args.clip))
                v_loss = 0.5 * (value - flat_targets[idx]) ** 2
                loss = pg + args.vf_coef * v_loss - args.ent_coef * entropy
                loss = (loss * mask).sum() / mask.sum().clamp(min=1)
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), 0.5)
                optimizer.step()

        done_steps = (update + 1) * n * steps
        recent = successes[-100:]
        print(f"steps {done_steps} | {done_steps / (time.perf_counter() - start):.0f} steps/s | "
              f"episodes {len(returns)} | return (last 100) "
              f"{np.mean(returns[-100:]) if returns else float('nan'):.2f} | success (last 100) "
              f"{np.mean(recent) if recent else float('nan'):.2f}", flush=True)
    envs.close()


if __name__ == "__main__":
    main()
