"""open_video_writer: H.264 through PyAV that OpenCV reads back, the mp4v fallback, atomic writes."""
from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest

from tbha_graph.mocap.io import video_writer as vw
from tbha_graph.mocap.io.video_writer import open_video_writer

W, H, N = 160, 120, 12


def frames():
    for i in range(N):
        f = np.full((H, W, 3), 40, np.uint8)
        cv2.rectangle(f, (10 + 5 * i, 30), (50 + 5 * i, 90), (0, 0, 230), -1)  # a red block moving right
        yield f


def read_back(path):
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        out.append(f)
    fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    return out, fps


def test_h264_is_read_back_by_opencv(tmp_path):
    av = pytest.importorskip("av")
    path = tmp_path / "clip.mp4"
    with open_video_writer(path, 25.0, W, H) as w:
        assert w.codec == "h264"
        for f in frames():
            w.write(f)
    got, fps = read_back(path)
    assert len(got) == N and got[0].shape == (H, W, 3) and fps == pytest.approx(25.0)
    assert np.abs(got[5][60, 40 + 25].astype(int) - (0, 0, 230)).max() < 40  # the block moved with the frames
    assert np.abs(got[5][60, 5].astype(int) - 40).max() < 20
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name == "h264" and s.codec_context.pix_fmt == "yuv420p"
    assert [p.name for p in tmp_path.iterdir()] == ["clip.mp4"]  # no temporary file left


def test_mp4v_fallback_and_odd_sizes(tmp_path, caplog):
    path = tmp_path / "clip.mp4"
    with open_video_writer(path, 30.0, W, H, codec="mp4v") as w:
        assert w.codec == "mp4v"
        for f in frames():
            w.write(f)
    got, fps = read_back(path)
    assert len(got) == N and got[0].shape == (H, W, 3) and fps == pytest.approx(30.0)
    # H.264 yuv420p cannot hold an odd size: auto falls back to mp4v and says why
    with caplog.at_level(logging.INFO, logger=vw.__name__):
        with open_video_writer(tmp_path / "odd.mp4", 30.0, W + 1, H, codec="auto") as w:
            w.write(np.zeros((H, W + 1, 3), np.uint8))
    assert w.codec == "mp4v" and "odd" in caplog.text
    with pytest.raises(ValueError, match="even"):
        open_video_writer(tmp_path / "odd2.mp4", 30.0, W + 1, H, codec="h264")


def test_missing_pyav_falls_back_with_a_note(tmp_path, monkeypatch):
    monkeypatch.setattr(vw, "pyav_available", lambda: False)
    notes = []
    with open_video_writer(tmp_path / "a.mp4", 30.0, W, H, note=notes.append) as w:
        w.write(np.zeros((H, W, 3), np.uint8))
    assert w.codec == "mp4v" and "PyAV is not installed" in notes[0]
    assert len(read_back(tmp_path / "a.mp4")[0]) == 1


@pytest.mark.parametrize("codec", ["h264", "mp4v"])
def test_error_leaves_nothing_and_bad_frames_are_refused(tmp_path, codec):
    if codec == "h264":
        pytest.importorskip("av")
    path = tmp_path / "clip.mp4"
    path.write_bytes(b"previous")  # an earlier result must survive a failed write
    with pytest.raises(ValueError, match=r"frame 1 is uint8 \(120, 100, 3\)"):
        with open_video_writer(path, 30.0, W, H, codec=codec) as w:
            w.write(np.zeros((H, W, 3), np.uint8))
            w.write(np.zeros((H, 100, 3), np.uint8))
    assert path.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["clip.mp4"]
    with pytest.raises(ValueError, match="codec"):
        open_video_writer(path, 30.0, W, H, codec="h265")
    with pytest.raises(ValueError, match="fps"):
        open_video_writer(path, 0.0, W, H)
