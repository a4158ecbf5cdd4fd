"""Fuzzing the BVH reader (``tbha_graph.mocap.io.bvh.read_bvh``) with damaged CMU files.

Base file: the real header of CMU 131_02 (31 joints, mixed CR/LF line endings, per-joint Euler
orders) and its first 3 motion lines. Property, per mutated file:

* it is rejected with a ``BvhError`` (a ``TbhaError``) whose message names the file and a line, or
* it is accepted, and then what was read is what the file says (checked independently of the
  reader: every motion token is a plain decimal number and the values equal the tokens; the OFFSET
  triples, channel names, frame count and frame time equal the tokens after their keywords), and it
  round-trips (written with ``write_bvh`` and read again: same joints, channels and values);
* never another exception, never a hang (10 s per case).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.mocap.io.bvh import read_bvh, write_bvh

CMU = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
N_MOTION_LINES = 3


def _base() -> bytes:
    lines = CMU.read_bytes().splitlines(keepends=True)
    k = next(i for i, s in enumerate(lines) if s.startswith(b"Frames:"))
    return b"".join(lines[:k]) + b"Frames: %d\r\n" % N_MOTION_LINES + b"".join(lines[k + 1: k + 2 + N_MOTION_LINES])


BASE = _base()
VOCAB = vocabulary(BASE[: BASE.index(b"MOTION") + 40])  # header words: ROOT, JOINT, {, }, OFFSET, CHANNELS, ...
STRICT_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_BREAKS = re.compile(r"\r\n|\r|\n")


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_bvh")


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def check_what_was_read(raw: bytes, bvh) -> None:
    """Compare the parsed file with the file's own tokens (an oracle independent of the reader)."""
    lines = _BREAKS.split(_decode(raw))
    m = next(i for i, s in enumerate(lines) if s.split()[:1] and s.split()[0].upper() == "MOTION")
    header = [w for s in lines[:m] for w in s.split()]
    rest = [s for s in lines[m + 1:] if s.strip()]
    frames_line, time_line, motion_lines = rest[0], rest[1], rest[2:]
    frames_tok, time_tok = frames_line.split(":")[1].strip(), time_line.split(":")[1].strip()
    assert re.fullmatch(r"[0-9]+", frames_tok) and int(frames_tok) == bvh.n_frames
    assert STRICT_NUMBER.fullmatch(time_tok) and float(time_tok) == bvh.frame_time
    tokens = [w for s in motion_lines for w in s.split()]
    bad = [w for w in tokens if not STRICT_NUMBER.fullmatch(w)]
    assert not bad, f"accepted motion values that are not numbers: {bad[:5]}"
    assert np.array_equal(np.array([float(w) for w in tokens]), bvh.motion.ravel())
    assert len(motion_lines) == bvh.n_frames and all(len(s.split()) == bvh.n_channels for s in motion_lines)
    # OFFSET triples (joints and End Sites) as written, in any order
    triples = []
    for i, w in enumerate(header):
        if w.upper() == "OFFSET":
            vals = header[i + 1: i + 4]
            bad = [v for v in vals if not STRICT_NUMBER.fullmatch(v)]
            assert not bad, f"accepted OFFSET values that are not numbers: {bad}"
            triples.append(tuple(float(v) for v in vals))
    parsed = [tuple(j.offset) for j in bvh.joints] + [tuple(j.end_site) for j in bvh.joints if j.end_site is not None]
    assert sorted(triples) == sorted(parsed)
    chans = [w.lower() for w in header if w.lower().endswith(("rotation", "position"))]
    assert chans == [c.lower() for j in bvh.joints for c in j.channels]


def check_round_trip(bvh, path: Path) -> None:
    back = read_bvh(write_bvh(path, bvh, precision=9))
    assert back.names == bvh.names
    assert np.array_equal(back.parents, bvh.parents)
    assert [j.channels for j in back.joints] == [j.channels for j in bvh.joints]
    assert np.allclose(back.offsets, bvh.offsets, rtol=1e-12, atol=1e-9)
    assert [j.end_site is None for j in back.joints] == [j.end_site is None for j in bvh.joints]
    assert back.frame_time == bvh.frame_time
    assert back.motion.shape == bvh.motion.shape and np.allclose(back.motion, bvh.motion, rtol=1e-12, atol=1e-9)


def check_bvh_file(raw: bytes, work: Path) -> None:
    path = work / "case.bvh"
    path.write_bytes(raw)
    with time_limit(what=f"read_bvh({path.name})"):
        try:
            bvh = read_bvh(path)
        except Exception as e:  # noqa: BLE001 - the property is about which exceptions escape
            assert_names_file(e, path, need_line=True)
            return
        check_what_was_read(raw, bvh)
        check_round_trip(bvh, work / "roundtrip.bvh")


def test_unmutated_base_parses(work) -> None:
    bvh = read_bvh(_write(work, BASE))
    assert bvh.n_frames == N_MOTION_LINES and len(bvh.joints) == 31
    check_what_was_read(BASE, bvh)


def _write(work: Path, raw: bytes) -> Path:
    p = work / "base.bvh"
    p.write_bytes(raw)
    return p


# Cases the fuzzer found (kept as explicit examples). A latin-1 byte 0xb3 is '³': '³'.isdigit() is
# True but int('³') raises ValueError; float() accepts '1_0' (= 10.0), so a damaged digit was read as
# a different number instead of being rejected; write_bvh encoded ASCII only (a non-ASCII joint name
# that read fine could not be written) and np.round(1.8e299, 9) overflows to inf, so a value that read
# fine was written as 'inf'.
FOUND = [
    case(BASE.replace(b"JOINT LeftHip", b"JOINT Left\x80Hip"), "non-ASCII joint name"),
    case(BASE.replace(b"JOINT LeftKnee", "JOINT LinkesKnie\u00e4".encode()), "UTF-8 joint name"),
    case(BASE.replace(b"\n4.8105 ", b"\n1.797693134862316e+299 ", 1), "huge motion value"),
    case(BASE.replace(b"OFFSET 1.24777", b"OFFSET 1.797693134862316e+299", 1), "huge OFFSET value"),
    case(BASE.replace(b"Frames: 3", b"Frames: \xb3"), "Frames: superscript three"),
    case(BASE.replace(b"CHANNELS 6", b"CHANNELS \xb3", 1), "channel count superscript three"),
    case(BASE.replace(b"OFFSET 1.24777", b"OFFSET 1.24_77", 1), "underscore inside an OFFSET number"),
    case(BASE.replace(b"Frame Time: .0083333", b"Frame Time: .008_3333"), "underscore inside the frame time"),
]


@pytest.mark.parametrize("raw", FOUND, ids=lambda c: c.what[0])
def test_found_cases(raw, work) -> None:
    check_bvh_file(raw, work)


@given(raw=mutated(BASE, VOCAB))
@fuzz_settings(max_examples=350)
def test_fuzz_bvh_reader(raw, work) -> None:
    CASES["bvh reader"] += 1
    check_bvh_file(raw, work)
