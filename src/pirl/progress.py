"""Progress of a long job (training steps, evaluation episodes), the one way every command shows
it: a live bar on a terminal; off one (a log, a test, a CI job), a plain line every
``every_s`` seconds and a final one."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any


class Progress:
    """One job's progress: ``update(done, total, info)``, then :meth:`close`.

    ``line`` formats the plain lines (fields ``label``, ``done``, ``total``, ``info``).
    ``bar``: a ``rich.progress.Progress`` the caller shows (its own console decides whether it
    is a terminal, ``tty``); without one, a bar of its own goes to stderr when that is a
    terminal. ``rate_unit`` adds the rate since the first update to ``info`` (start-up,
    compiling and loading, is not counted). ``final_at_total``: the line for ``done >=
    total`` is printed when it comes (a job that shares its bar goes on to other work);
    otherwise :meth:`close` prints the final line.
    """

    def __init__(
        self,
        label: str,
        total: int | None = None,
        line: str = "[{label}] {done:,}/{total:,} steps  {info}",
        every_s: float = 10.0,
        enabled: bool = True,
        bar: Any | None = None,
        tty: bool | None = None,
        rate_unit: str = "",
        final_at_total: bool = False,
        out: Callable[[str], Any] | None = None,
    ) -> None:
        self.label, self.total, self.line, self.every_s = label, total, line, every_s
        self.enabled, self.rate_unit, self.final_at_total = enabled, rate_unit, final_at_total
        self.out = out or (lambda text: print(text, flush=True))
        self.tty = enabled and (sys.stderr.isatty() if tty is None else tty)
        self.first: int | None = None
        self.first_t = self.last_log = time.perf_counter()
        self.done, self.info = 0, ""
        self._printed: tuple[int, int | None] | None = None
        self._own = bar is None and self.tty
        if self._own:
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn
            from rich.progress import Progress as RichProgress

            bar = RichProgress(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[info]}"),
                TimeRemainingColumn(),
                transient=False,
            )
            bar.start()
        self.bar = bar if enabled else None
        if self.bar is not None:
            self._task = self.bar.add_task(label, total=total, visible=self._own, info="")

    def update(self, done: int, total: int | None = None, info: str = "") -> None:
        """``done`` of ``total`` (None: the total given before); ``info`` follows the count."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if total is not None:
            self.total = total
        if self.first is None:  # the first update (or the resumed checkpoint's count)
            self.first, self.first_t, self.last_log = done, now, now
        if self.rate_unit:
            rate = (done - self.first) / max(1e-9, now - self.first_t)
            info = f"{rate:,.0f} {self.rate_unit}" + (f"  {info}" if info else "")
        self.done, self.info = done, info
        if self.bar is not None:
            shown = min(done, self.total) if self.total is not None else done
            self.bar.update(self._task, completed=shown, total=self.total, info=info, visible=True)
        if self.tty:
            return
        at_total = self.final_at_total and self.total is not None and done >= self.total
        if (
            at_total and self._printed != (done, self.total)
        ) or now - self.last_log >= self.every_s:
            self.last_log = now
            self._line()

    def __call__(self, done: int, total: int) -> None:
        """``update(done, total)``: the callback form evaluations take."""
        self.update(done, total)

    def _line(self) -> None:
        self._printed = (self.done, self.total)
        self.out(
            self.line.format(label=self.label, done=self.done, total=self.total, info=self.info)
        )

    def close(self) -> None:
        """Stop a bar of its own, or print the final plain line (once)."""
        if self._own and self.bar is not None:
            self.bar.stop()
        elif self.enabled and not self.tty and self.first is not None and not self.final_at_total:
            self._line()


__all__ = ["Progress"]
