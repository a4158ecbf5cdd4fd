"""Fuzzing the ground-truth reader (``tbha_graph.mocap.io.ground_truth.load_ground_truth``, node
``io.ground_truth``): a binary ``.npz`` (a zip of ``.npy`` arrays), damaged by byte/bit flips,
truncation, overwritten spans and the line-based mutations.

Bases: the first 3 frames of the bundled sample's ``ground_truth.npz``, saved with ``np.savez``
(stored) and ``np.savez_compressed`` (deflate). Property, per damaged file: a ``NodeError``
(``TbhaError``) naming the file, or a bundle whose every array equals the intact file's array of the
same name (or, when damage renamed members consistently, of another name: data is never damaged
silently); never another exception, never a hang.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit
from tbha_graph.mocap.io.ground_truth import load_ground_truth

SAMPLE = Path(__file__).resolve().parents[2] / "data" / "sample" / "ground_truth.npz"
PER_FRAME = ("joints3d_world", "joints3d_cam", "joints2d", "patch_centers_world", "patch2d", "patch_visible")

pytestmark = pytest.mark.skipif(not SAMPLE.is_file(), reason="data/sample/ground_truth.npz is missing")


def _arrays() -> dict[str, np.ndarray]:
    with np.load(SAMPLE, allow_pickle=False) as z:
        return {k: (z[k][:3] if k in PER_FRAME else z[k]) for k in z.files}


def _npz(compressed: bool) -> bytes:
    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **_arrays())
    return buf.getvalue()


ARRAYS = _arrays() if SAMPLE.is_file() else {}
BASES = {"stored": _npz(False), "deflated": _npz(True)} if SAMPLE.is_file() else {}


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_truth")


def check_truth_file(raw: bytes, work: Path) -> None:
    path = work / "ground_truth.npz"
    path.write_bytes(raw)
    with time_limit(what="load_ground_truth"):
        try:
            truth = load_ground_truth(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    for k, v in truth.items():
        # damaged zip structure may consistently rename members (two swapped names: a valid archive
        # that says something else); the data read must still be data of the intact file
        v = np.asarray(v)
        same = k in ARRAYS and np.array_equal(v, ARRAYS[k])
        assert same or any(np.array_equal(v, a) and v.dtype == a.dtype for a in ARRAYS.values()), \
            f"array {k!r} is not data of the intact file"


def test_intact_files_read(work) -> None:
    for raw in BASES.values():
        check_truth_file(raw, work)
        assert set(load_ground_truth(work / "ground_truth.npz")) == set(ARRAYS)


def _retyped(raw: bytes, member: bytes, old: bytes, new: bytes) -> bytes:
    """``raw`` with the first ``old`` after ``member``'s name (its .npy header) replaced by ``new``."""
    i = raw.index(old, raw.index(member))
    return raw[:i] + new + raw[i + len(old):]


# Cases the fuzzer found (kept as explicit examples): BadZipFile, zlib.error, NotImplementedError
# ("compression method not supported") and RuntimeError ("encrypted") escaped as bare exceptions; and
# numpy reads only the bytes a .npy header asks for, so with a member larger than zipfile's 4 kB read
# chunk a damaged header declaring a smaller dtype was read without the zip's CRC check: the whole
# joints3d_world came back as garbage, silently (found by reasoning from a fuzz case in which damaged
# zip structure renamed members; shown on the full-size file).
def _full_stored() -> bytes:
    buf = io.BytesIO()
    with np.load(SAMPLE, allow_pickle=False) as z:
        np.savez(buf, **{k: z[k] for k in z.files})
    return buf.getvalue()


FOUND = [
    case(_retyped(_full_stored(), b"joints3d_world.npy", b"<f8", b"<f4"),
         "all 210 frames, stored: '<f4' in the header of an 80 kB '<f8' member (read silently as garbage)"),
    case(BASES["stored"][: len(BASES["stored"]) // 2], "stored npz cut in half (no central directory)"),
    case(BASES["deflated"][:200] + bytes(64) + BASES["deflated"][264:], "zeroed bytes inside deflated data"),
    case(_retyped(BASES["stored"], b"height.npy", b"<i8", b"<i1"), "a smaller dtype in a .npy header"),
    case(_retyped(BASES["stored"], b"K.npy", b"(3, 3)", b"(3, 1)"), "a smaller shape in a .npy header"),
] if BASES else []


@pytest.mark.parametrize("raw", FOUND, ids=lambda c: c.what[0])
def test_found_cases(raw, work) -> None:
    check_truth_file(raw, work)


@pytest.mark.parametrize("kind", ["stored", "deflated"])
@given(data=st.data())
@fuzz_settings(max_examples=100)
def test_fuzz_ground_truth_npz(work, kind, data) -> None:
    CASES[f"ground truth npz ({kind})"] += 1
    raw = data.draw(st.one_of(
        mutated(BASES[kind]),
        st.tuples(st.integers(0, len(BASES[kind]) - 1), st.binary(min_size=1, max_size=32)).map(
            lambda t: BASES[kind][: t[0]] + t[1] + BASES[kind][t[0] + len(t[1]):]),
    ), label="damaged npz")
    check_truth_file(raw, work)
