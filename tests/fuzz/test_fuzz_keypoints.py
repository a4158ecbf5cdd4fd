"""Fuzzing the detector keypoint readers: MediaPipe Pose JSON and CSV
(``tbha_graph.mocap.io.mediapipe_keypoints.read_mediapipe``, used by ``io.mediapipe_keypoints`` and
``io.mediapipe_world``) and OpenPose ``--write_json`` folders
(``tbha_graph.mocap.io.openpose_keypoints.read_openpose``).

Bases: the first frames of the bundled keypoint files made from CMU 131_02
(``data/keypoints/cmu131_02``); the CSV is the same landmarks in the CSV layout. Property, per mutated
file: a ``NodeError`` (``TbhaError``) whose message names the file, or a result equal to what an
independent parse of the file says, where every value read is a number written as a number (no
``true`` read as 1, no ``"0.5"`` string, no ``1_0``); never another exception, never a hang.
"""
from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.mocap.io.keypoint_layouts import MEDIAPIPE_POSE
from tbha_graph.mocap.io.mediapipe_keypoints import read_mediapipe
from tbha_graph.mocap.io.openpose_keypoints import read_openpose

KP = Path(__file__).resolve().parents[2] / "data" / "keypoints" / "cmu131_02"
N_FRAMES = 2
STRICT_INT = re.compile(r"-?[0-9]+")
STRICT_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?(?:nan|inf|infinity)", re.I)

pytestmark = pytest.mark.skipif(not KP.is_dir(), reason="data/keypoints/cmu131_02 is missing")


def _mp_doc() -> dict:
    doc = json.loads((KP / "mediapipe.json").read_text())
    return {**doc, "frames": doc["frames"][:N_FRAMES]}


def _mp_json() -> bytes:
    doc = _mp_doc()
    head = json.dumps({k: v for k, v in doc.items() if k != "frames"})[:-1]
    lines = [json.dumps(f, separators=(",", ":")) for f in doc["frames"]]
    return (head + ', "frames": [\n' + ",\n".join(lines) + "\n]}\n").encode()


def _mp_csv() -> bytes:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["frame", "landmark", "x", "y", "z", "visibility", "world_x", "world_y", "world_z"])
    for fr in _mp_doc()["frames"]:
        for i, (lm, wl) in enumerate(zip(fr["landmarks"], fr["world_landmarks"])):
            name = MEDIAPIPE_POSE.landmarks[i] if i % 5 == 0 else str(i)  # both index and name forms
            w.writerow([fr["frame"], name, lm["x"], lm["y"], lm["z"], lm["visibility"], wl["x"], wl["y"], wl["z"]])
    return out.getvalue().encode()


MP_JSON = _mp_json() if KP.is_dir() else b""
MP_CSV = _mp_csv() if KP.is_dir() else b""
OP_FILES = sorted((KP / "openpose").glob("*.json"))[:3] if KP.is_dir() else []
OP_BASE = [p.read_bytes() for p in OP_FILES]


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_keypoints")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _rows(items) -> np.ndarray:
    out = []
    for lm in items:
        vals = [lm["x"], lm["y"], lm.get("z", 0.0), lm.get("visibility", 1.0)] if isinstance(lm, dict) else list(lm)
        assert all(_is_number(v) for v in vals[:4]), f"a landmark that is not numbers was accepted: {lm!r}"
        out.append((vals + [1.0] * 4)[:4] if not isinstance(lm, dict) else vals)
    return np.array(out, dtype=np.float64)


def check_mp_json_result(raw: bytes, take) -> None:
    doc = json.loads(raw)
    frames = doc["frames"] if isinstance(doc, dict) else doc
    assert take.image.shape[0] == len(frames)
    for k, fr in enumerate(frames):
        for key, alt, arr in (("landmarks", "pose_landmarks", take.image), ("world_landmarks", "pose_world_landmarks", take.world)):
            items = fr.get(key, fr.get(alt))
            if items:
                assert np.array_equal(_rows(items), arr[k]), f"frame {k}: {key} differ from the file"
            elif arr is not None:
                assert np.isnan(arr[k]).all()


def check_mp_csv_result(raw: bytes, take) -> None:
    rows = [r for r in csv.reader(io.StringIO(raw.decode("utf-8"), newline="")) if r and any(c.strip() for c in r)]
    header = [h.strip().lower() for h in rows[0]]
    col = {h: i for i, h in enumerate(header)}
    frames = []
    for r in rows[1:]:
        assert STRICT_INT.fullmatch(r[col["frame"]].strip()), f"frame number {r[col['frame']]!r} accepted"
        frames.append(int(r[col["frame"]]))
        for k in ("x", "y", "z", "visibility", "world_x", "world_y", "world_z"):
            if k in col and r[col[k]].strip():
                assert STRICT_NUMBER.fullmatch(r[col[k]].strip()), f"{k} = {r[col[k]]!r} accepted as a number"
    first = min(frames)
    assert take.first_frame == first and take.image.shape[0] == max(frames) - first + 1
    names = {n: i for i, n in enumerate(MEDIAPIPE_POSE.landmarks)}
    for r in rows[1:]:
        lm = r[col["landmark"]].strip()
        i = int(lm) if STRICT_INT.fullmatch(lm) else names[lm.lower()]
        f = int(r[col["frame"]]) - first
        x, y = (r[col[k]].strip() for k in ("x", "y"))
        if x and y:
            assert take.image[f, i, 0] == float(x) and take.image[f, i, 1] == float(y)


def check_openpose_result(raws: list[bytes], out: np.ndarray) -> None:
    assert out.shape[0] == len(raws)
    for k, raw in enumerate(raws):
        people = json.loads(raw)["people"]
        for person in people:
            kp = person.get("pose_keypoints_2d", person.get("pose_keypoints"))
            assert all(_is_number(v) for v in kp), "a keypoint that is not a number was accepted"
        if len(people) == 1:
            kp = people[0].get("pose_keypoints_2d", people[0].get("pose_keypoints"))
            assert np.array_equal(np.asarray(kp, dtype=np.float64).reshape(-1, 3), out[k])
        elif not people:
            assert not out[k].any()


def check_mediapipe_file(raw: bytes, suffix: str, work: Path) -> None:
    path = work / f"mediapipe{suffix}"
    path.write_bytes(raw)
    with time_limit(what=f"read_mediapipe({path.name})"):
        try:
            take = read_mediapipe(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    (check_mp_json_result if suffix == ".json" else check_mp_csv_result)(raw, take)


def check_openpose_folder(raws: list[bytes], work: Path) -> None:
    folder = work / "openpose"
    folder.mkdir(exist_ok=True)
    for p in folder.iterdir():
        p.unlink()
    for src, raw in zip(OP_FILES, raws):
        (folder / src.name).write_bytes(raw)
    with time_limit(what="read_openpose"):
        try:
            out, _, _ = read_openpose(folder)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, folder, need_line=False)
            return
    check_openpose_result(raws, out)


def test_unmutated_keypoint_files_read(work) -> None:
    check_mediapipe_file(MP_JSON, ".json", work)
    check_mediapipe_file(MP_CSV, ".csv", work)
    check_openpose_folder(OP_BASE, work)
    assert read_mediapipe(work / "mediapipe.csv").image.shape == (N_FRAMES, 33, 4)


# cases the fuzzer found (kept as explicit examples)
FOUND_JSON = [
    case(MP_JSON.replace(b'"x":0.49112', b'"x":true', 1), "true as a coordinate"),
    case(MP_JSON.replace(b'"x":0.49112', b'"x":"0.49112"', 1), "a string as a coordinate"),
    case(MP_JSON.replace(b'"width": 640', b'"width": 6\xe90', 1), "a byte that is not UTF-8"),
]
FOUND_CSV = [
    case(MP_CSV.replace(b"\n0,1,", b"\n0,\xc2\xb9,", 1), "superscript one as the landmark index"),
    case(MP_CSV.replace(b"\n1,1,", b"\n1_0,1,", 1), "an underscore in a frame number"),
    case(MP_CSV.replace(b"\n0,1,", b"\n0,1\x00,", 1), "a NUL byte"),
    case(MP_CSV.replace(b"\n0,1,", b"\n0,\xe9,", 1), "a byte that is not UTF-8"),
]
FOUND_OPENPOSE = [
    [OP_BASE[0].replace(b'"pose_keypoints_2d":[313.376', b'"pose_keypoints_2d":[true', 1)] + OP_BASE[1:],
    [OP_BASE[0].replace(b'"version":1.3', b'"version":1.\xe93', 1)] + OP_BASE[1:],
]


@pytest.mark.parametrize("raw", FOUND_JSON, ids=lambda c: c.what[0])
def test_found_mediapipe_json_cases(raw, work) -> None:
    check_mediapipe_file(raw, ".json", work)


@pytest.mark.parametrize("raw", FOUND_CSV, ids=lambda c: c.what[0])
def test_found_mediapipe_csv_cases(raw, work) -> None:
    check_mediapipe_file(raw, ".csv", work)


@pytest.mark.parametrize("raws", FOUND_OPENPOSE, ids=["true as a coordinate", "a byte that is not UTF-8"])
def test_found_openpose_cases(raws, work) -> None:
    check_openpose_folder(raws, work)


@given(raw=mutated(MP_JSON, vocabulary(MP_JSON[:200]) + (b"null", b"[]", b"true", b'"x"')))
@fuzz_settings(max_examples=160)
def test_fuzz_mediapipe_json(raw, work) -> None:
    CASES["mediapipe json"] += 1
    check_mediapipe_file(raw, ".json", work)


@given(raw=mutated(MP_CSV, (b",", b"nose", b"frame", b"x", b"\"")))
@fuzz_settings(max_examples=160)
def test_fuzz_mediapipe_csv(raw, work) -> None:
    CASES["mediapipe csv"] += 1
    check_mediapipe_file(raw, ".csv", work)


@given(which=st.integers(0, 2), raw=st.data())
@fuzz_settings(max_examples=120)
def test_fuzz_openpose_folder(which, raw, work) -> None:
    CASES["openpose folder"] += 1
    raws = list(OP_BASE)
    raws[which] = raw.draw(mutated(OP_BASE[which], (b"people", b"pose_keypoints_2d", b"[]", b"{}", b"null", b"true")))
    check_openpose_folder(raws, work)
