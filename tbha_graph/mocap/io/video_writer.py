"""Writing videos that browsers and common players open: H.264 through PyAV, mp4v through OpenCV.

:func:`open_video_writer` returns a :class:`VideoWriter` taking BGR ``uint8`` frames of shape
``(height, width, 3)``. Codecs:

* ``"h264"``: H.264 (libx264, ``yuv420p``, ``+faststart``) in an mp4 container, written with PyAV
  (``av``, an optional dependency). Plays in browsers, QuickTime, VLC, and OpenCV reads it back.
  ``yuv420p`` needs an even width and height.
* ``"mp4v"``: MPEG-4 part 2 through ``cv2.VideoWriter`` (always available, but browsers do not play it).
* ``"auto"`` (default): ``"h264"`` when PyAV is importable and the size is even, else ``"mp4v"`` with a
  logged note saying why.

Writing is atomic: frames go to a hidden temporary file in the destination folder, renamed onto
``path`` by :meth:`VideoWriter.close`; on an error (or :meth:`VideoWriter.abort`) the temporary file is
removed and ``path`` is left untouched. Use it as a context manager::

    with open_video_writer("out.mp4", fps=30, width=640, height=480) as w:
        for frame in frames:
            w.write(frame)
"""
from __future__ import annotations

import logging
from fractions import Fraction
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ...core.atomic import commit, discard, temp_path

log = logging.getLogger(__name__)

CODECS = ("auto", "h264", "mp4v")
#: libx264 constant rate factor: 0 = lossless, 23 = x264's default, 18-20 = visually near lossless
DEFAULT_CRF = 20


def pyav_available() -> bool:
    """True when PyAV (``import av``) can be imported (H.264 writing is then possible)."""
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


class VideoWriter:
    """Base of the writers: frame checks, atomic rename, context manager. ``codec`` names the codec
    actually used (``"h264"`` or ``"mp4v"``); ``frames`` counts frames written."""

    codec = ""

    def __init__(self, path: Path, fps: float, width: int, height: int):
        self.path = Path(path)
        self.fps = float(fps)
        self.width = int(width)
        self.height = int(height)
        self.frames = 0
        self._tmp = temp_path(self.path if self.path.suffix else self.path.with_name(self.path.name + ".mp4"))  # OpenCV picks the container from the suffix
        self._closed = False

    # --- subclass hooks -------------------------------------------------------------------------
    def _write(self, frame: np.ndarray) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _finish(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _release(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    # --- public API -----------------------------------------------------------------------------
    def write(self, frame_bgr: np.ndarray) -> None:
        """Append one BGR ``uint8`` frame ``(height, width, 3)``; raises ``ValueError`` for another shape."""
        if self._closed:
            raise ValueError(f"video writer for {self.path} is already closed")
        f = np.asarray(frame_bgr)
        if f.dtype != np.uint8 or f.shape != (self.height, self.width, 3):
            raise ValueError(
                f"video {self.path}: frame {self.frames} is {f.dtype} {f.shape}, expected uint8 "
                f"({self.height}, {self.width}, 3) BGR"
            )
        self._write(np.ascontiguousarray(f))
        self.frames += 1

    def close(self) -> Path:
        """Flush, close, and move the finished file onto ``path`` (returned)."""
        if self._closed:
            return self.path
        try:
            self._finish()
        except BaseException:
            self.abort()
            raise
        self._closed = True
        commit(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Stop writing and remove the temporary file; ``path`` is not created or changed."""
        if not self._closed:
            self._closed = True
            try:
                self._release()
            except Exception:  # noqa: BLE001 - already failing; never mask the original error
                pass
        discard(self._tmp)

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


#: libx264's threading: frames encoded on its own threads (outside the GIL; the output is deterministic), ~25 %
#: faster than PyAV's default ``"SLICE"`` at 640x480 (``python bench/video_encode.py``)
H264_THREADS = "FRAME"


class _PyAvWriter(VideoWriter):
    """H.264 (libx264, yuv420p) in mp4 through PyAV."""

    codec = "h264"

    def __init__(self, path: Path, fps: float, width: int, height: int, crf: int, preset: str):
        super().__init__(path, fps, width, height)
        import av

        self._av = av
        rate = Fraction(self.fps).limit_denominator(1001)
        self._container = av.open(str(self._tmp), mode="w", format="mp4", options={"movflags": "+faststart"})
        try:
            stream = self._container.add_stream("libx264", rate=rate)
            stream.width, stream.height, stream.pix_fmt = self.width, self.height, "yuv420p"
            stream.codec_context.time_base = 1 / rate
            stream.options = {"crf": str(int(crf)), "preset": preset}
            stream.codec_context.thread_type = H264_THREADS
        except BaseException:
            self._container.close()
            discard(self._tmp)
            raise
        self._stream = stream

    def _write(self, frame: np.ndarray) -> None:
        vf = self._av.VideoFrame.from_ndarray(frame, format="bgr24")
        vf.pts = self.frames
        self._container.mux(self._stream.encode(vf))

    def _finish(self) -> None:
        self._container.mux(self._stream.encode(None))
        self._container.close()

    def _release(self) -> None:
        self._container.close()


class _OpenCvWriter(VideoWriter):
    """MPEG-4 part 2 (``mp4v``) through ``cv2.VideoWriter``."""

    codec = "mp4v"

    def __init__(self, path: Path, fps: float, width: int, height: int):
        super().__init__(path, fps, width, height)
        self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (self.width, self.height))
        if not self._writer.isOpened():
            self._writer.release()
            discard(self._tmp)
            raise OSError(f"OpenCV cannot open an mp4v writer for {self.path} (is the folder writable?)")

    def _write(self, frame: np.ndarray) -> None:
        self._writer.write(frame)

    def _finish(self) -> None:
        self._writer.release()

    def _release(self) -> None:
        self._writer.release()


def open_video_writer(
    path: str | Path,
    fps: float,
    width: int,
    height: int,
    codec: str = "auto",
    *,
    crf: int = DEFAULT_CRF,
    preset: str = "superfast",
    note: Callable[[str], None] | None = None,
) -> VideoWriter:
    """Open an atomic video writer for ``path`` (frames BGR ``uint8`` ``(height, width, 3)``, ``fps`` Hz).

    ``codec``: ``"auto"``, ``"h264"`` or ``"mp4v"`` (see the module docstring). ``crf`` and ``preset``
    tune libx264 (ignored for mp4v). ``note`` receives a one-line message when ``"auto"`` falls back to
    mp4v (default: the module logger at INFO level; nodes pass ``ctx.log``).

    Raises ``ValueError`` for a bad codec, size or fps, or ``"h264"`` requested with an odd size;
    ``ImportError`` for ``"h264"`` without PyAV.
    """
    if codec not in CODECS:
        raise ValueError(f"unknown video codec {codec!r}: use one of {CODECS}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"video {path}: fps must be a positive number, got {fps}")
    if int(width) <= 0 or int(height) <= 0:
        raise ValueError(f"video {path}: size must be positive, got {width}x{height}")
    path = Path(path)
    odd = int(width) % 2 or int(height) % 2
    if codec == "h264" and odd:
        raise ValueError(f"video {path}: H.264 (yuv420p) needs an even width and height, got {width}x{height}; use codec 'mp4v' or 'auto'")
    if codec == "auto":
        reason = "" if pyav_available() else "PyAV is not installed (pip install av)"
        if not reason and odd:
            reason = f"the size {width}x{height} is odd (H.264 yuv420p needs even sizes)"
        codec = "mp4v" if reason else "h264"
        if reason:
            (note or log.info)(f"writing {path.name} as mp4v, which browsers do not play, because {reason}")
    if codec == "h264":
        return _PyAvWriter(path, fps, width, height, crf=crf, preset=preset)
    return _OpenCvWriter(path, fps, width, height)
