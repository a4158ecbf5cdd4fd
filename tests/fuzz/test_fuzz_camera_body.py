"""Fuzzing the camera file reader (``calibrate.known``: ``read_camera_file``, YAML / JSON / npz) and the
bone-length measurements reader (``reconstruct.bone_lengths``: ``read_measurements``, YAML / JSON).

Bases: the bundled sample's camera (K, R, t, size, distortion) and the default bone lengths, written
as each format. Property, per damaged file: a ``NodeError`` (``TbhaError``) naming the file, or a
result equal to what an independent parse of the file says, from a file without duplicate keys,
where every value is a number written as a number (no ``true`` read as 1, no ``640.5`` pixels cut to
640); for npz, every value equals the intact file's; never another exception, never a hang.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.core.yamlfile import load_yaml
from tbha_graph.mocap.calibrate.known import read_camera_file
from tbha_graph.mocap.reconstruct.bone_lengths import read_measurements
from tbha_graph.mocap.body import lengths_to_body
from tbha_graph.mocap.skeleton import bone_lengths_array

SAMPLE = Path(__file__).resolve().parents[2] / "data" / "sample" / "ground_truth.npz"


def _camera() -> dict:
    if SAMPLE.is_file():
        with np.load(SAMPLE, allow_pickle=False) as z:
            K, R, t, w, h = (z[k] for k in ("K", "R", "t", "width", "height"))
    else:
        K, R, t, w, h = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]]), np.eye(3), np.array([0.0, -1, 4]), 640, 480
    return {"K": K.tolist(), "R": R.tolist(), "t": t.tolist(), "width": int(w), "height": int(h),
            "dist": [0.01, -0.002, 0.0, 0.0, 0.0]}


CAMERA = _camera()
CAM_YAML = yaml.safe_dump({"camera": CAMERA}, default_flow_style=None, sort_keys=False).encode()
CAM_JSON = json.dumps(CAMERA, indent=1).encode()


def _cam_npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in CAMERA.items()})
    return buf.getvalue()


CAM_NPZ = _cam_npz()
BODY = {k: round(v, 4) for k, v in lengths_to_body(bone_lengths_array()).items()}
BODY_YAML = yaml.safe_dump(BODY, sort_keys=False).encode()
BODY_JSON = json.dumps(BODY, indent=1).encode()


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_camera_body")


def _numbers_only(x) -> bool:
    if isinstance(x, list):
        return all(_numbers_only(v) for v in x)
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _duplicate_keys(path: Path) -> bool:
    _, problems = load_yaml(path)
    return any("duplicate key" in p.message for p in problems)


def check_camera_file(raw: bytes, suffix: str, work: Path) -> None:
    path = work / f"camera{suffix}"
    path.write_bytes(raw)
    with time_limit(what="read_camera_file"):
        try:
            cam = read_camera_file(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    got = {"K": cam.K, "R": cam.R, "t": cam.t, "width": cam.width, "height": cam.height, "dist": cam.dist}
    if suffix == ".npz":
        for k, v in got.items():
            assert np.array_equal(np.asarray(v, dtype=np.float64).reshape(-1)[: np.size(CAMERA[k])],
                                  np.asarray(CAMERA[k], dtype=np.float64).reshape(-1)), f"{k} differs from the intact file's"
        return
    if suffix == ".yaml":
        assert not _duplicate_keys(path), "a camera file with duplicate keys was accepted"
        data = yaml.safe_load(raw)
    else:
        data = json.loads(raw)
    if isinstance(data.get("camera"), dict):
        data = data["camera"]
    for k, v in got.items():
        if k not in data:
            continue
        assert _numbers_only(data[k]), f"{k}: {data[k]!r} is not numbers, but was accepted"
        want = np.asarray(data[k], dtype=np.float64).reshape(-1)
        have = np.asarray(v, dtype=np.float64).reshape(-1)
        if k == "dist" and want.size == 8:  # OpenCV's (k1, k2, p1, p2, k3, k4, k5, k6) with k4..k6 = 0
            want = want[:5]
        assert np.array_equal(have[: want.size], want), f"{k}: the file says {data[k]!r}, the camera has {v!r}"


def check_body_file(raw: bytes, suffix: str, work: Path) -> None:
    path = work / f"body{suffix}"
    path.write_bytes(raw)
    with time_limit(what="read_measurements"):
        try:
            body = read_measurements(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    if suffix == ".yaml":
        assert not _duplicate_keys(path), "a bone length file with duplicate keys was accepted"
        data = yaml.safe_load(raw) or {}
    else:
        data = json.loads(raw)
    assert body == {str(k): float(v) for k, v in data.items()}
    assert all(_numbers_only(v) for v in data.values())


def test_intact_files_read(work) -> None:
    for raw, suffix in ((CAM_YAML, ".yaml"), (CAM_JSON, ".json"), (CAM_NPZ, ".npz")):
        check_camera_file(raw, suffix, work)
        assert read_camera_file(work / f"camera{suffix}").width == CAMERA["width"]
    for raw, suffix in ((BODY_YAML, ".yaml"), (BODY_JSON, ".json")):
        check_body_file(raw, suffix, work)
        assert read_measurements(work / f"body{suffix}") == BODY


# cases the fuzzer found (kept as explicit examples)
FOUND_CAMERA = [
    (case(CAM_YAML.replace(b"width: ", b"width: \xe9", 1), "a byte that is not UTF-8"), ".yaml"),
    (case(CAM_YAML.replace(b"  width:", b"  height: 7\n  width:", 1), "a duplicated key"), ".yaml"),
    (case(CAM_JSON.replace(b'"width": 640', b'"width": 640.5', 1), "a fractional image width"), ".json"),
    (case(CAM_JSON.replace(b'"width": 640', b'"width": true', 1), "true as the image width"), ".json"),
    (case(CAM_NPZ[: len(CAM_NPZ) // 2], "npz cut in half"), ".npz"),
    (case(CAM_YAML.replace(b"  width:", b"  7: 1\n  width:", 1).replace(b"  K:", b"  k:", 1), "a number as a key, a key missing"), ".yaml"),
]
FOUND_BODY = [
    (case(BODY_YAML.replace(b"chest:", b"ch\xe9st:", 1), "a byte that is not UTF-8"), ".yaml"),
    (case(BODY_YAML + BODY_YAML.splitlines(keepends=True)[0].replace(b": ", b": 9"), "a duplicated key"), ".yaml"),
    (case(BODY_YAML.replace(b"chest: 0.224", b"chest: " + b"9" * 40, 1), "a 40-digit integer length"), ".yaml"),
    (case(BODY_YAML.replace(b"chest: 0.224", b"chest: " + b"9" * 400, 1), "a 400-digit integer length"), ".yaml"),
]


@pytest.mark.parametrize("raw,suffix", FOUND_CAMERA, ids=lambda c: c.what[0] if hasattr(c, "what") else c)
def test_found_camera_cases(raw, suffix, work) -> None:
    check_camera_file(raw, suffix, work)


@pytest.mark.parametrize("raw,suffix", FOUND_BODY, ids=lambda c: c.what[0] if hasattr(c, "what") else c)
def test_found_body_cases(raw, suffix, work) -> None:
    check_body_file(raw, suffix, work)


CAM_BASES = {".yaml": CAM_YAML, ".json": CAM_JSON, ".npz": CAM_NPZ}


@pytest.mark.parametrize("suffix", [".yaml", ".json", ".npz"])
@given(data=st.data())
@fuzz_settings(max_examples=80)
def test_fuzz_camera_file(work, suffix, data) -> None:
    CASES[f"camera file ({suffix})"] += 1
    base = CAM_BASES[suffix]
    check_camera_file(data.draw(mutated(base, vocabulary(base) if suffix != ".npz" else ()), label="file"), suffix, work)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
@given(data=st.data())
@fuzz_settings(max_examples=80)
def test_fuzz_bone_length_file(work, suffix, data) -> None:
    CASES[f"bone length file ({suffix})"] += 1
    base = BODY_YAML if suffix == ".yaml" else BODY_JSON
    check_body_file(data.draw(mutated(base, vocabulary(base)), label="file"), suffix, work)
