"""Progress on a terminal, silence in pipes and CI: long runs show a bar only when stderr is a
terminal, so redirected output stays clean."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO


class Progress:
    """A one-line bar, ``label [#####.....] done/total unit, elapsed``, redrawn in place on
    ``stream`` (stderr) when that is a terminal; with ``enabled=False``, or when the stream is not
    a terminal, nothing is written."""

    WIDTH = 30

    def __init__(
        self, label: str, total: int, unit: str = "", enabled: bool | None = None, stream: TextIO | None = None
    ):
        self.label, self.total, self.unit = label, max(int(total), 0), unit
        self.stream = sys.stderr if stream is None else stream
        self.enabled = self.stream.isatty() if enabled is None else bool(enabled)
        self.start = time.perf_counter()
        self.done = 0

    def update(self, done: int) -> None:
        """Shows ``done`` of ``total``; the line ends once all are done."""
        self.done = min(int(done), self.total)
        if not self.enabled:
            return
        filled = self.WIDTH * self.done // self.total if self.total else self.WIDTH
        bar = "#" * filled + "." * (self.WIDTH - filled)
        unit = f" {self.unit}" if self.unit else ""
        end = "\n" if self.done >= self.total else ""
        self.stream.write(
            f"\r{self.label} [{bar}] {self.done}/{self.total}{unit}, {time.perf_counter() - self.start:.0f} s{end}"
        )
        self.stream.flush()

    def advance(self, n: int = 1) -> None:
        self.update(self.done + n)


def callback(
    progress: bool | Callable[[int, int], object], label: str, unit: str = ""
) -> Callable[[int, int], object] | None:
    """A ``(done, total)`` callback for the core's long runs: ``progress`` itself when it is
    callable, a :class:`Progress` bar (drawn on a terminal only) when it is True, else None."""
    if callable(progress):
        return progress
    if not progress:
        return None
    bar: Progress | None = None

    def report(done: int, total: int) -> None:
        nonlocal bar
        if bar is None or bar.total != total:
            bar = Progress(label, total, unit)
        bar.update(done)

    return report
