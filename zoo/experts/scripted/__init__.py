"""Scripted privileged expert: BFS planning over the full game state (no pixels)."""

from zoo.experts.scripted.config import ExpertConfig
from zoo.experts.scripted.policy import ScriptedExpert

__all__ = ["ExpertConfig", "ScriptedExpert"]
