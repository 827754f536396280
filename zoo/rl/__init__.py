"""Reference RL agents on the task suites: PPO written once (``ppo``), the envs it steps
(``envs``), the networks it trains (``policies``), the loop (``train``) and ``zoo rl``."""
