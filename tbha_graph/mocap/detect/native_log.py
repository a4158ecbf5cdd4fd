"""MediaPipe's own info and warning lines kept off the user's terminal.

MediaPipe's C++ graph and TensorFlow Lite write straight to the process's standard error (file descriptor 2), past
Python: ``INFO: Created TensorFlow Lite XNNPACK delegate for CPU.``, ``WARNING: All log messages before
absl::InitializeLog() is called are written to STDERR`` and one ``W0000 00:00:... inference_feedback_manager.cc:114]
Feedback manager requires a model with a single signature inference. ...`` per Pose, none of which says anything a user
can act on. No environment variable turns them off (``GLOG_minloglevel`` and ``TF_CPP_MIN_LOG_LEVEL`` do not reach
absl's logging, which the Python package never initialises).

:func:`filtered_stderr` puts a pipe in place of descriptor 2 while a block runs; a thread copies what arrives to the
real standard error as it comes, except MediaPipe's lines (:data:`CHATTER`, :func:`chatter_start`), which it counts. Errors (absl's
``E``/``F`` lines) and everything else, this program's own progress and log lines included, pass. Setting the
environment variable ``TBHA_MEDIAPIPE_LOG=1`` leaves descriptor 2 alone (every line shown): the way to see everything
should the process die inside MediaPipe, when what was still in the pipe is lost with it.
"""
from __future__ import annotations

import os
import re
import sys
import threading
from contextlib import contextmanager
from typing import Iterator

#: Lines dropped: TensorFlow Lite's delegate notice, absl's note on its own initialisation, and absl's info and
#: warning lines (``I``/``W``, ``MMDD hh:mm:ss.micros thread file:line]``; before absl is initialised the seconds
#: field holds the seconds since 1970), each from where it starts to the line's end
CHATTER = re.compile(
    rb"(INFO: Created TensorFlow Lite "
    rb"|WARNING: All log messages before absl::InitializeLog\(\) is called are written to STDERR"
    rb"|[IW]\d{4} \d\d:\d\d:\d+\.\d+ +\d+ [\w./-]+:\d+\] )"
)

#: Environment variable that, set to 1, shows MediaPipe's own lines as they are
SHOW_ENV = "TBHA_MEDIAPIPE_LOG"


def chatter_start(line: bytes) -> int | None:
    """Where in ``line`` (without its newline) one of MediaPipe's lines starts, or None: at 0 for a line of its own,
    further on where it was written after another program's unfinished line (a progress bar's, ended by ``\\r``)."""
    m = CHATTER.search(line)
    return None if m is None else m.start()


class _Filter:
    """Reads the pipe (descriptor ``read_fd``) and writes to ``out_fd`` all but the chatter lines. A partial line is
    held back only while it could still become chatter (it starts with ``I`` or ``W``), so a progress bar's carriage
    returns reach the terminal at once."""

    def __init__(self, read_fd: int, out_fd: int):
        self.read_fd, self.out_fd = read_fd, out_fd
        self.hidden = 0
        self.thread = threading.Thread(target=self._run, name="mediapipe-log-filter", daemon=True)

    def _write(self, data: bytes) -> None:
        while data:
            try:
                data = data[os.write(self.out_fd, data):]
            except OSError:  # the real stderr is gone: drop what is left
                return

    def _run(self) -> None:
        held = b""
        while True:
            chunk = os.read(self.read_fd, 65536)
            if not chunk:
                break
            held += chunk
            while b"\n" in held:
                line, held = held.split(b"\n", 1)
                at = chatter_start(line)
                if at is None:
                    self._write(line + b"\n")
                else:  # what came before it on the line (a progress bar's text) passes
                    self.hidden += 1
                    self._write(line[:at])
            if held and not held.startswith((b"I", b"W")):
                self._write(held)
                held = b""
        if held:
            at = chatter_start(held)
            self._write(held if at is None else held[:at])
        os.close(self.read_fd)


_lock = threading.Lock()
_depth = 0
_active: _Filter | None = None


@contextmanager
def filtered_stderr() -> Iterator[list[int]]:
    """While the block runs, descriptor 2 goes through a pipe that drops MediaPipe's info and warning lines (module
    docstring). Yields a one-item list that holds, once the block has ended, how many lines have been dropped since
    the filter was put in place (blocks that overlap, nested or in other threads, share one filter: the first puts it
    in place, the last takes it away and has the full count; the others, what the filter had read by their end). Leaves descriptor 2 alone with ``TBHA_MEDIAPIPE_LOG=1`` or where it cannot be
    duplicated."""
    global _depth, _active
    count = [0]
    if os.environ.get(SHOW_ENV) == "1":
        yield count
        return
    with _lock:
        if _active is None:
            try:
                saved = os.dup(2)
            except OSError:  # no standard error to filter
                saved = None
            if saved is not None:
                read_fd, write_fd = os.pipe()
                _sync_python_stderr()
                os.dup2(write_fd, 2)
                os.close(write_fd)
                _active = _Filter(read_fd, saved)
                _active.thread.start()
        flt = _active
        if flt is not None:
            _depth += 1
    if flt is None:
        yield count
        return
    try:
        yield count
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _sync_python_stderr()
                os.dup2(flt.out_fd, 2)  # the pipe's last writer closed: the thread reads to its end and stops
                flt.thread.join(timeout=5.0)
                if not flt.thread.is_alive():  # else a child process still holds the pipe: leave the thread its descriptor
                    os.close(flt.out_fd)
                _active = None
        count[0] = flt.hidden


def _sync_python_stderr() -> None:
    """Python's buffered text on sys.stderr written out before descriptor 2 changes."""
    try:
        sys.stderr.flush()
    except (AttributeError, ValueError, OSError):
        pass
