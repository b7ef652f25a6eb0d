"""Progress of a long envelope computation: cells done, rate and ETA on a terminal or in a log."""

from __future__ import annotations

import logging
import math
import sys
import time
from typing import IO

__all__ = ["NullProgress", "Progress"]

log = logging.getLogger(__name__)


class Progress:
    """Cells done, rate and ETA: a redrawn bar on an interactive terminal, else a log line every ~10 %/10 s."""

    def __init__(self, stream: IO[str] | None = None, interactive: bool | None = None, label: str = "") -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.interactive = self.stream.isatty() if interactive is None else interactive
        self.label = label
        self._phase, self._total, self._done, self._started, self._shown = "", 0, 0, 0.0, 0.0
        self._last_fraction = -1.0

    def start(self, phase: str, total: int) -> None:
        self._phase, self._total, self._done = phase, total, 0
        self._started = self._shown = time.monotonic()
        self._last_fraction = -1.0
        if total:
            self._show(force=True)

    def advance(self, count: int = 1) -> None:
        self._done += count
        self._show(force=self._done >= self._total)

    def finish(self) -> None:
        if self.interactive and self._total:
            self.stream.write("\n")
            self.stream.flush()

    def message(self, text: str) -> None:
        if self.interactive:
            self.stream.write("\r\033[K")
        self.stream.write(text + "\n")
        self.stream.flush()

    def _show(self, force: bool = False) -> None:
        now = time.monotonic()
        elapsed = now - self._started
        rate = self._done / elapsed if elapsed > 0 else 0.0
        remaining = (self._total - self._done) / rate if rate > 0 else math.nan
        fraction = self._done / self._total if self._total else 1.0
        eta = f"ETA {remaining:5.0f} s" if math.isfinite(remaining) else "ETA    ? s"
        prefix = f"{self.label}{self._phase}"
        if self.interactive:
            if not force and now - self._shown < 0.1:
                return
            width = 30
            bar = "#" * int(width * fraction) + "-" * (width - int(width * fraction))
            self.stream.write(f"\r\033[K{prefix} [{bar}] {self._done}/{self._total} {rate:6.1f}/s {eta}")
        else:
            if not force and fraction - self._last_fraction < 0.1 and now - self._shown < 10.0:
                return
            self._last_fraction = fraction
            self.stream.write(f"{prefix}: {self._done}/{self._total} ({100 * fraction:.0f} %), {rate:.1f}/s, {eta}\n")
        self._shown = now
        self.stream.flush()


class NullProgress(Progress):
    """Reports nothing (library use without a progress display)."""

    def __init__(self) -> None:
        super().__init__(stream=sys.stderr, interactive=False)

    def start(self, phase: str, total: int) -> None:
        pass

    def advance(self, count: int = 1) -> None:
        pass

    def finish(self) -> None:
        pass

    def message(self, text: str) -> None:
        log.info("%s", text)
