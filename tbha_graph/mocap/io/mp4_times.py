"""The frame times an MP4 or QuickTime (.mov) file states for its video, read from its index without decoding.

Phones record at a variable frame rate (fewer frames a second in dim light, a frame dropped when the encoder
falls behind); OpenCV hands the frames over one after another with the file's average rate, so a capture that
spaces them evenly at that rate gets the motion's timing wrong where they are not. The container says when each
frame is shown: the video track's ``mdhd`` gives its timescale (ticks a second), ``stts`` each sample's duration in
decoding order and ``ctts`` (when frames are reordered, B-frames) each sample's offset from decoding to showing.

Boxes are ``size`` (32-bit big-endian, 1: a 64-bit size follows, 0: to the end of the file) and a four-character
type; ``moov/trak/mdia`` holds ``mdhd``, ``hdlr`` (``vide`` for video) and ``minf/stbl`` with the tables. Only the
boxes' headers and those tables are read. Fragmented files (``moof``, no sample table) give no times.
"""
from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

_CONTAINERS = {b"moov", b"trak", b"mdia", b"minf", b"stbl"}
#: largest sample table read (entries): a day of video at 240 fps has fewer
_MAX_ENTRIES = 25_000_000


def _boxes(f: BinaryIO, start: int, end: int):
    """``(type, data offset, data end)`` of the boxes in ``[start, end)``."""
    at = start
    while at + 8 <= end:
        f.seek(at)
        size, kind = struct.unpack(">I4s", f.read(8))
        head = 8
        if size == 1:
            size = struct.unpack(">Q", f.read(8))[0]
            head = 16
        elif size == 0:
            size = end - at
        if size < head or at + size > end:
            return  # a box running past its parent: a damaged or cut file, read no further
        yield kind, at + head, at + size
        at += size


def _table(f: BinaryIO, at: int, end: int, signed: bool = False) -> np.ndarray | None:
    """A ``stts``/``ctts`` table: ``(entries, 2)`` of (sample count, value), or None when it does not fit its box."""
    f.seek(at)
    version_flags, n = struct.unpack(">II", f.read(8))
    if n > _MAX_ENTRIES or at + 8 + 8 * n > end:
        return None
    dtype = ">i4" if signed and version_flags >> 24 == 1 else ">u4"
    raw = np.frombuffer(f.read(8 * n), dtype=">u4").reshape(n, 2)
    return np.stack([raw[:, 0].astype(np.int64), raw[:, 1].view(dtype).astype(np.int64)], axis=1)


def _video_track(f: BinaryIO, trak: int, end: int) -> tuple[int, np.ndarray, np.ndarray | None] | None:
    """``(timescale, stts, ctts or None)`` when the ``trak`` box holds a video track with a sample table."""
    scale = kind = stts = ctts = None
    for box, at, box_end in _boxes(f, trak, end):
        if box != b"mdia":
            continue
        for sub, sub_at, sub_end in _boxes(f, at, box_end):
            f.seek(sub_at)
            if sub == b"mdhd":
                version = f.read(4)[0]
                f.seek(sub_at + (20 if version == 1 else 12))
                scale = struct.unpack(">I", f.read(4))[0]
            elif sub == b"hdlr":
                f.seek(sub_at + 8)
                kind = f.read(4)
            elif sub == b"minf":
                for stbl, st_at, st_end in _boxes(f, sub_at, sub_end):
                    if stbl != b"stbl":
                        continue
                    for tab, tab_at, tab_end in _boxes(f, st_at, st_end):
                        if tab == b"stts":
                            stts = _table(f, tab_at, tab_end)
                        elif tab == b"ctts":
                            ctts = _table(f, tab_at, tab_end, signed=True)
    if kind != b"vide" or not scale or stts is None or len(stts) == 0:
        return None
    return scale, stts, ctts


def frame_times(path: str | Path) -> np.ndarray | None:
    """Seconds at which the file's first video track shows each frame ``(n_frames,)``, in showing order (the order
    OpenCV decodes them), from the first; None when the file is not an MP4/QuickTime file with a sample table."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            size = path.stat().st_size
            if size < 16:
                return None
            f.seek(4)
            if f.read(4) not in (b"ftyp", b"moov", b"wide", b"free", b"mdat", b"skip"):
                return None
            for kind, at, end in _boxes(f, 0, size):
                if kind != b"moov":
                    continue
                for trak, t_at, t_end in _boxes(f, at, end):
                    if trak != b"trak":
                        continue
                    found = _video_track(f, t_at, t_end)
                    if found is not None:
                        return _showing_times(*found)
    except (OSError, struct.error, ValueError):
        return None
    return None


def _showing_times(scale: int, stts: np.ndarray, ctts: np.ndarray | None) -> np.ndarray | None:
    durations = np.repeat(stts[:, 1], stts[:, 0])
    decode = np.concatenate([[0], np.cumsum(durations[:-1])])
    if ctts is not None:
        offsets = np.repeat(ctts[:, 1], ctts[:, 0])
        if len(offsets) != len(decode):
            return None  # the two tables disagree on the frame count
        decode = decode + offsets
    shown = np.sort(decode)
    return (shown - shown[0]) / float(scale)


#: an interval this many times the median or longer is a dropped frame (2: one frame missing; 1.5 would catch a
#: 20 fps stretch of a 30 fps take, which the tolerance already counts)
GAP = 1.75


def uneven_frame_times(times: np.ndarray, start: int = 0, stop: int | None = None, tolerance: float = 0.1) -> dict | None:
    """How uneven the intervals between frames ``start .. stop - 1`` are, or None when they are even: more than 1 %
    of them (and at least 2) off the median interval by more than ``tolerance``, or any one :data:`GAP` times the
    median or longer (a dropped frame). Returns ``{"median_ms", "min_ms", "max_ms", "off", "intervals", "gaps":
    [frame, ...]}`` (``gaps``: frames that follow such an interval; ``off``: intervals off by more than the
    tolerance)."""
    t = np.asarray(times, dtype=float)[start:stop]
    if len(t) < 3:
        return None
    d = np.diff(t)
    med = float(np.median(d))
    if med <= 0:
        return None
    off = np.abs(d / med - 1.0) > tolerance
    gaps = np.flatnonzero(d >= GAP * med) + start + 1
    if not (off.sum() > max(1, 0.01 * len(d)) or len(gaps)):
        return None
    return {"median_ms": 1e3 * med, "min_ms": 1e3 * float(d.min()), "max_ms": 1e3 * float(d.max()),
            "off": int(off.sum()), "intervals": int(len(d)), "gaps": [int(g) for g in gaps]}
