"""Experts that generate CrafterPlay: a scripted privileged planner and a PPO-RNN (Craftax)."""
