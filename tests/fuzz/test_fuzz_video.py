"""Fuzzing the video reader (``io.video``: ``probe_video`` + ``iter_frames``) with truncated and
corrupted files.

Bases: 30 frames of 160x120 noise with the frame number drawn in, written as mp4 (mp4v) and AVI
(MJPG) by ``cv2.VideoWriter``, and as H.264 mp4 (``+faststart``: the index is at the start) by the
project's PyAV writer when ``av`` is installed. Properties:

* truncated at a random byte: ``probe_video`` refuses the file with a ``NodeError`` naming it, or
  ``iter_frames`` yields every frame, each equal to that frame of the intact file, or it stops with a
  ``NodeError`` naming the file and the frame where decoding failed (= the number of frames it
  yielded), every frame it yielded but the last equal to the intact file's (the last one, cut short,
  may be decoded with concealed errors; the error right after it stops the run). An MJPG AVI cut
  inside a frame (OpenCV decodes it with concealed errors and reports nothing) stops at that frame:
  ``io.video`` reads the AVI's chunk sizes (``test_mjpg_cut_inside_its_last_frame_is_detected``);
* bytes overwritten at a random place: the same, except that decoded frames may differ (a decoder
  cannot tell damaged image data from an image, nor a damaged header declaring another frame size
  from a real one), but every frame has the size ``probe_video`` reported;
* a ``tbha-run`` of a pipeline reading a truncated video fails naming the frame, exits 1, and writes
  no run directory.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzlib import CASES, assert_names_file, fuzz_settings, time_limit
from tbha_graph.mocap.io.video import iter_frames, probe_video

N, W, H, FPS = 30, 160, 120, 30.0


def _frames() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    out = []
    for i in range(N):
        img = cv2.GaussianBlur((rng.random((H, W, 3)) * 255).astype(np.uint8), (5, 5), 0)
        cv2.putText(img, str(i), (30, 80), cv2.FONT_HERSHEY_SIMPLEX, 2, (255, 255, 255), 3)
        out.append(img)
    return out


def _write_cv2(path: Path, fourcc: str) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), FPS, (W, H))
    for f in _frames():
        w.write(f)
    w.release()
    return path


def _write_h264(path: Path) -> Path:
    from tbha_graph.mocap.io.video_writer import open_video_writer

    with open_video_writer(path, fps=FPS, width=W, height=H, codec="h264") as w:
        for f in _frames():
            w.write(f)
    return path


def _have_av() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


KINDS = ["mp4v.mp4", "mjpg.avi"] + (["h264.mp4"] if _have_av() else [])


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> dict[str, dict]:
    """Per kind: the intact file's bytes and its decoded frames."""
    d = tmp_path_factory.mktemp("fuzz_video")
    out = {}
    for kind in KINDS:
        path = d / f"intact_{kind}"
        if kind == "h264.mp4":
            _write_h264(path)
        else:
            _write_cv2(path, "mp4v" if kind.startswith("mp4v") else "MJPG")
        frames = [f for _, f in iter_frames(probe_video(path))]
        assert len(frames) == N
        out[kind] = {"bytes": path.read_bytes(), "frames": frames, "dir": d}
    return out


def check_video(raw: bytes, kind: str, base: dict, exact: bool) -> None:
    path = base["dir"] / f"case_{kind}"
    path.write_bytes(raw)
    got = 0
    differs: list[int] = []
    with time_limit(what=f"reading {path.name}"):
        try:
            clip = probe_video(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
        if exact:  # a corrupted header may declare another size; then every frame must have that size
            assert (clip.width, clip.height) == (W, H)
        try:
            for index, frame in iter_frames(clip):
                assert index == clip.start + got
                assert frame.shape == (clip.height, clip.width, 3) and frame.dtype == np.uint8
                if exact and not np.array_equal(frame, base["frames"][index]):
                    differs.append(index)
                got += 1
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            m = re.search(r"frame (\d+)", e.message)
            assert m and int(m.group(1)) == clip.start + got, f"the error does not name the failing frame {got}: {e}"
            assert not [i for i in differs if i != clip.start + got - 1], f"frames {differs} decoded differently from the intact file"
            return
    assert got == clip.n_frames
    assert not differs, f"frames {differs} decoded differently from the intact file, and no error"


def _last_jpeg(raw: bytes) -> tuple[int, int]:
    """Byte range of the last JPEG image (SOI .. EOI) in an MJPG AVI."""
    start = raw.rindex(b"\xff\xd8\xff")
    return start, raw.index(b"\xff\xd9", start) + 2


@pytest.mark.parametrize("kind", KINDS)
@given(data=st.data())
@fuzz_settings(max_examples=40)
def test_fuzz_truncated_video(videos, kind, data) -> None:
    CASES[f"video truncated ({kind})"] += 1
    raw = videos[kind]["bytes"]
    cut = data.draw(st.integers(0, len(raw) - 1), label="truncated at byte")
    check_video(raw[:cut], kind, videos[kind], exact=True)


def test_mjpg_cut_inside_its_last_frame_is_detected(videos) -> None:
    """OpenCV decodes a JPEG cut short with concealed errors and reports nothing; io.video finds the cut from the
    AVI's chunk sizes (``io.avi_cut``) and stops there, naming the frame."""
    raw = videos["mjpg.avi"]["bytes"]
    a, b = _last_jpeg(raw)
    check_video(raw[: (a + b) // 2], "mjpg.avi", videos["mjpg.avi"], exact=True)


@pytest.mark.parametrize("kind", KINDS)
@given(data=st.data())
@fuzz_settings(max_examples=40)
def test_fuzz_corrupted_video(videos, kind, data) -> None:
    CASES[f"video corrupted ({kind})"] += 1
    raw = bytearray(videos[kind]["bytes"])
    at = data.draw(st.integers(0, len(raw) - 1), label="at byte")
    junk = data.draw(st.one_of(st.binary(min_size=1, max_size=64), st.integers(1, 20000).map(bytes)), label="junk")
    raw[at:at + len(junk)] = junk
    check_video(bytes(raw), kind, videos[kind], exact=False)


def test_truncated_video_in_a_pipeline(videos, tmp_path) -> None:
    """tbha-run stops at the frame that cannot be decoded, exit 1, and presents no output."""
    kind = "h264.mp4" if "h264.mp4" in KINDS else "mjpg.avi"
    raw = videos[kind]["bytes"]
    video = tmp_path / f"cut.{kind.split('.')[1]}"
    video.write_bytes(raw[: len(raw) // 2])
    pipeline = tmp_path / "segment.yaml"
    pipeline.write_text(
        "description: decode a video and segment it\n"
        "nodes:\n"
        f"  decode: {{type: io.video, params: {{path: {video.name}}}}}\n"
        "  colors: {type: color.rg_chromaticity}\n"
        "  segment: {type: segment.chroma_threshold, inputs: {video: decode.video, colors: colors.model}}\n"
        "outputs: {detections.npz: segment.detections}\n"
    )
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "tbha_graph.cli.run", str(pipeline), "--out", str(out), "--no-cache", "--quiet"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert re.search(r"decoding failed at frame \d+", proc.stderr) and str(video) in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([video.name, pipeline.name])
