"""Progress reporting: one line per node (ran / cached, time) and a bar for long loops over frames.

Bars (tqdm) appear only on a terminal; in a log or CI the per-node lines are all that is printed.
"""
from __future__ import annotations

import sys
import threading
from typing import Any, Iterable, Iterator, TextIO, TypeVar

T = TypeVar("T")


class Reporter:
    """Prints node lines to ``stream``; ``quiet`` prints nothing; ``bars`` defaults to ``stream.isatty()``."""

    def __init__(self, stream: TextIO | None = None, quiet: bool = False, bars: bool | None = None):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.bars = (not quiet) and (bars if bars is not None else bool(getattr(self.stream, "isatty", lambda: False)()))
        self._lock = threading.Lock()  # nodes on several threads (run_local with jobs > 1): whole lines

    def _print(self, text: str) -> None:
        if self.quiet:
            return
        with self._lock:
            if self.bars:  # tqdm.write clears the bars (several nodes' at once with jobs > 1), prints, redraws them
                from tqdm import tqdm

                tqdm.write(text, file=self.stream)
                self.stream.flush()
            else:
                print(text, file=self.stream, flush=True)

    def node_done(self, node_id: str, type_name: str, status: str, seconds: float, note: str = "") -> None:
        if self.quiet:  # the scheduler calls this once per node: format nothing when nothing is printed
            return
        self._print(f"  {status:<7} {node_id:<22} {type_name:<30} {seconds:8.2f} s{('  ' + note) if note else ''}")

    def warn(self, text: str) -> None:
        self._print(f"  warning: {text}")

    def log(self, node_id: str, msg: str) -> None:
        self._print(f"          {node_id}: {msg}")

    def progress(self, node_id: str, iterable: Iterable[T], total: int | None = None, desc: str = "") -> Iterator[T]:
        if not self.bars:
            return iter(iterable)
        from tqdm import tqdm

        return iter(tqdm(iterable, total=total, desc=f"  {node_id}{': ' + desc if desc else ''}", leave=False, file=self.stream, unit="fr"))


QUIET = Reporter(quiet=True)


def fmt_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)
