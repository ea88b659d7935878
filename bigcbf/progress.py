"""Progress of a long episode on stderr: one line, updated in place, only on a terminal.

The bench shows its progress as a tqdm bar on stderr when stderr is a terminal and prints nothing of it in logs
or CI (``bigcbf.bench.runner.run_bench``); an episode that renders a video (about 5 times the episode's own time)
does the same with :class:`EpisodeProgress`: simulated time against the time limit, frames written, wall time::

    video x.mp4:  43%|████▎     | 5.6/13.0 s simulated, 112 frames [00:06]

The line stays on screen when the episode ends (the final summary). Any observer of an Episode can use it.
"""
from __future__ import annotations

import sys
from typing import Callable, TextIO

#: the simulated seconds are shown to 0.1 s
_BAR = "{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s simulated{postfix} [{elapsed}]"


class EpisodeProgress:
    """Call with each control step's record (``rec.t``, simulated seconds); ``close()`` at the end.

    ``time_limit_s``: the episode's time limit (the bar's end; an episode that reaches its goal earlier ends
    short of it). ``frames``: a callable giving the frames written so far (shown when given). ``enabled``: None
    shows it only when ``stream`` is a terminal (as the bench's bar). ``stream``: default sys.stderr."""

    def __init__(self, time_limit_s: float, desc: str = "episode", *, frames: Callable[[], int] | None = None,
                 enabled: bool | None = None, stream: TextIO | None = None, mininterval: float = 0.2):
        from tqdm import tqdm
        stream = stream if stream is not None else sys.stderr
        if enabled is None:
            isatty = getattr(stream, "isatty", None)
            enabled = bool(isatty and isatty())
        self.enabled = enabled
        self.frames = frames
        self.t = 0.0
        self._bar = tqdm(total=round(float(time_limit_s), 1), desc=desc, file=stream, disable=not enabled,
                         bar_format=_BAR, dynamic_ncols=True, mininterval=mininterval, leave=True)

    def _postfix(self, note: str | None = None) -> str:
        parts = [f"{self.frames()} frames"] if self.frames is not None else []
        if note:
            parts.append(note)
        return ", ".join(parts)     # (tqdm puts ", " before it)

    def __call__(self, rec) -> None:
        self.update(float(rec.t))

    def update(self, t: float, note: str | None = None) -> None:
        """Simulated time ``t`` reached (the line is redrawn at most every ``mininterval`` seconds)."""
        if not self.enabled:
            return
        self.t = t
        bar = self._bar
        bar.n = round(min(t, bar.total), 1)
        bar.postfix = self._postfix(note)
        bar.refresh() if note else bar.update(0)

    def close(self, note: str | None = None) -> None:
        """The final line (``note``, e.g. "interrupted", after the counts), then a newline."""
        if self.enabled and not self._bar.disable:
            self._bar.n = round(min(self.t, self._bar.total), 1)
            self._bar.postfix = self._postfix(note)
        self._bar.close()
