"""The success window a PPO log reports, without the bias of "the last 100 that ended".

Short episodes end first: a success that takes 50 steps ends many times while a death after
300 steps is still running, so the episodes that *ended* recently over-represent the short
outcome (the first windows of a run the most; a C-VPT-RL run logged 95% where its episodes,
counted in seed order, succeeded 80%). Episodes here are counted in the order they started
(their seed index): the window is the last ``size`` episodes of the longest run of indices
that have all ended, so which episodes it holds never depends on how they turned out. It lags
the run by the longest episode in flight (at most the task's step limit).
"""

from __future__ import annotations

from collections import deque


class SeedOrderWindow:
    """Last ``size`` episodes of the gap-free prefix of ended episodes, counted from ``start``
    (the first episode index of this run or resume: episodes in flight at a checkpoint are
    dropped, so a resumed run starts a new prefix)."""

    def __init__(self, size: int = 100, start: int = 0) -> None:
        if size < 1:
            raise ValueError(f"window size must be >= 1, got {size}")
        self.next = start
        self._pending: dict[int, object] = {}
        self._window: deque = deque(maxlen=size)

    def add(self, episodes) -> None:
        """Record ended episodes (objects with an ``episode`` index), in any order."""
        for e in episodes:
            if e.episode < self.next or e.episode in self._pending:
                raise ValueError(f"episode {e.episode} ended twice")
            self._pending[e.episode] = e
        while self.next in self._pending:
            self._window.append(self._pending.pop(self.next))
            self.next += 1

    @property
    def episodes(self) -> list:
        """The window's episodes, oldest first; empty until it holds ``size`` of them (a
        window of the first few would be the noisiest number of the run)."""
        return list(self._window) if len(self._window) == self._window.maxlen else []
