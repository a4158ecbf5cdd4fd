"""Where an AVI file is cut short: the first video frame whose data runs past the end of the file.

OpenCV decodes a Motion-JPEG frame cut short with concealed errors and reports nothing, so a copy of a take
that stopped inside its last frame would be read as whole. The AVI container says how long each chunk is, so the
cut can be found without decoding: walk the RIFF chunks (``RIFF``/``LIST`` headers: a four-character code and a
little-endian 32-bit size, data padded to an even length), find the video stream (the ``strl`` whose ``strh``
says ``vids``; streams are numbered in the order of their ``strl`` lists), and count its chunks in ``movi``
(``NNdc`` or ``NNdb``, ``NN`` the stream number, inside ``LIST rec `` groups too). Only chunk headers are read.
OpenDML files (further ``RIFF AVIX`` parts) are walked the same way.
"""
from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

_HEADER = struct.Struct("<4sI")


def _chunks(f: BinaryIO, start: int, end: int, size: int):
    """``(fourcc, data offset, data length)`` of the chunks in ``[start, end)``; stops at the file's ``size``."""
    at = start
    while at + 8 <= min(end, size):
        f.seek(at)
        fourcc, length = _HEADER.unpack(f.read(8))
        yield fourcc, at + 8, length
        at += 8 + length + (length & 1)


def _video_stream(f: BinaryIO, hdrl: int, end: int, size: int) -> int | None:
    """The number of the first video stream declared in ``LIST hdrl`` (data from ``hdrl`` to ``end``)."""
    number = 0
    for fourcc, at, length in _chunks(f, hdrl + 4, end, size):
        if fourcc != b"LIST":
            continue
        f.seek(at)
        if f.read(4) != b"strl":
            continue
        for sub, sub_at, _ in _chunks(f, at + 4, at + length, size):
            if sub == b"strh":
                f.seek(sub_at)
                if f.read(4) == b"vids":
                    return number
                break
        number += 1
    return None


def _frames(f: BinaryIO, start: int, end: int, size: int, state: dict):
    """``(data offset, data length)`` of the video stream's chunks in the list data ``[start, end)``, in file order
    (``movi`` and its ``rec `` groups walked where they stand; ``state['ids']`` set from ``hdrl`` on the way)."""
    for fourcc, at, length in _chunks(f, start, end, size):
        if fourcc == b"LIST":
            f.seek(at)
            kind = f.read(4)
            if kind == b"hdrl" and not state["ids"]:
                stream = _video_stream(f, at, at + length, size)
                if stream is not None:
                    state["ids"] = (b"%02ddc" % stream, b"%02ddb" % stream)
            elif kind in (b"movi", b"rec "):
                yield from _frames(f, at + 4, at + length, size, state)
        elif fourcc in state["ids"]:
            yield at, length


def avi_cut_frame(path: str | Path) -> int | None:
    """The index of the first video frame of the AVI file ``path`` whose data the file does not hold entirely
    (frames from there on cannot be trusted), or None: not an AVI, or every frame's data is there."""
    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as f:
        head = f.read(12)
        if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"AVI ":
            return None
        state: dict = {"ids": ()}
        frame = 0
        for riff, riff_at, riff_len in _chunks(f, 0, size, size):  # the RIFF parts: AVI, then any AVIX
            if riff != b"RIFF":
                break
            for at, length in _frames(f, riff_at + 4, riff_at + riff_len, size, state):
                if at + length > size:
                    return frame
                frame += 1
    return None
