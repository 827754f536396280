"""What the paper's scale will cost: `zoo scale` measures each training stage on the CPU (FLOPs,
saved activations, a timed step) and projects GPU memory, GPU-hours, loader workers and disk.

Kept free of heavy imports: ``zoo --help`` imports ``lit_models.scale.cli`` to list the command.
Modules: ``stages`` (the paper configs as measurable stages), ``measure`` (torch counting and
timing), ``ppo`` (the same for the JAX PPO expert), ``project`` (GPUs, assumptions and the
arithmetic), ``report`` (scale.md and scale.json), ``cli`` (the command).
"""
