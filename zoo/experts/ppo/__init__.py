"""The paper's expert: PPO-RNN trained on Craftax-Classic-Symbolic (JAX), and its agent.

``train_ppo(PPOConfig.from_yaml("configs/expert_ppo.yaml"), "runs/expert_ppo")`` trains;
``PPOExpert.load("runs/expert_ppo", num_envs)`` plays the newest checkpoint in ``CraftaxEnv``.
"""

from zoo.experts.ppo.agent import PPOExpert
from zoo.experts.ppo.config import PPOConfig
from zoo.experts.ppo.run import train_ppo

__all__ = ["PPOConfig", "PPOExpert", "train_ppo"]
