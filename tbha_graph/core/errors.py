"""Error types of the framework. User errors carry a location and a hint and print without a traceback."""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Iterable


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest candidate, or ``""`` (the one shared helper)."""
    cands = [str(c) for c in candidates]
    close = difflib.get_close_matches(str(name), cands, n=1, cutoff=0.6)
    if not close:
        low = {c.lower(): c for c in cands}
        close = difflib.get_close_matches(str(name).lower(), list(low), n=1, cutoff=0.6)
        close = [low[c] for c in close]
    return f" (did you mean '{close[0]}'?)" if close else ""


@dataclass(frozen=True)
class Location:
    """Where something was written: file, 1-based line and column (0 when unknown)."""

    file: str = "<python>"
    line: int = 0
    column: int = 0

    def __str__(self) -> str:
        if self.line:
            return f"{self.file}:{self.line}:{self.column}" if self.column else f"{self.file}:{self.line}"
        return self.file


class TbhaError(Exception):
    """Base of all errors meant for a user: printed as a message, never as a traceback."""

    def __init__(self, message: str, *, hint: str = "", location: Location | None = None, node: str | None = None):
        self.message = message
        self.hint = hint
        self.location = location
        self.node = node
        super().__init__(self.format())

    def format(self) -> str:
        parts = []
        if self.location is not None:
            parts.append(f"{self.location}: ")
        if self.node:
            parts.append(f"node '{self.node}': ")
        parts.append(self.message)
        if self.hint:
            parts.append(f"\n  hint: {self.hint}")
        return "".join(parts)


class PortTypeError(TbhaError):
    """A value does not match its port type."""


class RegistryError(TbhaError):
    """A node type cannot be registered or found."""


class PipelineError(TbhaError):
    """One problem in a pipeline file."""


class PipelineErrors(TbhaError):
    """All problems found in a pipeline file at once."""

    def __init__(self, errors: list[PipelineError]):
        self.errors = list(errors)
        n = len(self.errors)
        body = "\n".join(f"  {i + 1}. {e.format()}".replace("\n  hint:", "\n     hint:") for i, e in enumerate(self.errors))
        super().__init__(f"{n} problem{'s' if n != 1 else ''} in the pipeline:\n{body}")

    def format(self) -> str:  # the message already holds everything
        return self.message


class NodeError(TbhaError):
    """Raised by a node for bad input it can explain (a missing file, a video with no frames...).

    The scheduler adds the node id; give the file/frame and what to do in ``message``/``hint``."""


class NodeFailed(TbhaError):
    """A node raised while running; wraps the original error with the node id and how to resume."""


class CacheError(TbhaError):
    """The cache could not be read or written."""
