"""Build the env PPO steps and the network it trains for each agent of ``RLConfig``."""

from __future__ import annotations

from torch import nn

from zoo.envs.constants import NUM_ACTIONS
from zoo.rl.config import RLConfig
from zoo.rl.envs import PlannerEnv, TaskVecEnv
from zoo.rl.policies import CVPTRLPolicy, FrameEncoder, RecurrentActorCritic

FRAME_SIZE = 144


def build_pixel_policy(config: RLConfig) -> nn.Module:
    """The freshly initialised network of a pixel agent (PPO-RNN or C-VPT-RL): what a run
    starts from, and what ``zoo eval`` loads a run's trained parameters into."""
    if config.agent == "ppo_rnn":
        hidden = config.hidden_size
        encoder = FrameEncoder(FRAME_SIZE, config.input_downsample, hidden)
        return RecurrentActorCritic(encoder, hidden, hidden, NUM_ACTIONS).to(config.device)
    if config.agent == "cvpt_rl":
        from zoo.weights import load_model

        model = load_model(config.pretrained().checkpoint, "cvpt")
        return CVPTRLPolicy(model, config.lora_rank, config.lora_alpha).to(config.device)
    raise ValueError(
        f"agent {config.agent!r} does not act on pixels alone (PPO-Steve's planner acts through "
        "C-Steve-1 in its own env); expected ppo_rnn or cvpt_rl"
    )


def build_agent(config: RLConfig, next_episode: int = 0, sampling_seed: int = 0):
    """(env, policy) for ``config``; episodes are numbered from ``next_episode`` (a resume),
    and PPO-Steve's executor samples its actions from ``sampling_seed``."""
    tasks = TaskVecEnv.make(config.task, config.env, config.num_envs, config.seed, next_episode)
    hidden = config.hidden_size
    if config.agent in ("ppo_rnn", "cvpt_rl"):
        return tasks, build_pixel_policy(config)
    steve, goals = load_executor(config)
    env = PlannerEnv(tasks, steve, goals, config.option_steps, sampling_seed)
    return env, planner_network(env.obs_dim, hidden, env.num_actions).to(config.device)


def load_executor(config: RLConfig):
    """PPO-Steve's frozen C-Steve-1 (with the config's CFG scale) and the goal of each of the
    61 captions: the prior's mean goal of its text, as ``zoo play`` gives text to C-Steve-1."""
    from zoo.agents.csteve1_agent import GoalEncoder, CSteve1Policy
    from zoo.captions.vocabulary import load_vocabulary

    spec = config.pretrained()
    spec.require_text()  # the config's goal models, else the ones its export records
    steve = CSteve1Policy.load(spec.checkpoint, config.device, cfg_scale=spec.cfg_scale,
                               cclip=spec.cclip, prior=spec.prior)
    models = steve.goal_model_paths()
    encoder = GoalEncoder.load(models["cclip"], models["prior"], sample_prior=False)
    return steve, encoder.from_caption_ids(list(range(len(load_vocabulary().texts()))))


def planner_network(obs_dim: int, hidden: int, num_captions: int) -> RecurrentActorCritic:
    """PPO-Steve's planner: a dense layer on its observation, a GRU, caption logits, value."""
    planner_input = nn.Sequential(nn.Linear(obs_dim, hidden), nn.ReLU())
    return RecurrentActorCritic(planner_input, hidden, hidden, num_captions)
