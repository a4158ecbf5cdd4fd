"""io.video: describing a video file, streaming its frames, and the errors users meet."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.core.types import hash_file
from tbha_graph.mocap.io import video as video_module
from tbha_graph.mocap.io.avi_cut import avi_cut_frame
from tbha_graph.mocap.io.video import iter_frames, iter_frames_at, video
from tbha_graph.mocap.segment.testframes import write_video

W, H, N = 128, 64, 24


def _coded_frame(i: int) -> np.ndarray:
    """A frame whose index is written as 8 black/white stripes (survives compression)."""
    f = np.zeros((H, W, 3), np.uint8)
    for b in range(8):
        if (i >> b) & 1:
            f[:, b * 16 : (b + 1) * 16] = 255
    return f


def _decode(f: np.ndarray) -> int:
    w = f.shape[1]
    return sum(1 << b for b in range(8) if f[f.shape[0] // 2, int((b + 0.5) * w / 8)].mean() > 128)


@pytest.fixture(scope="module")
def coded_mp4(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "coded.mp4"
    write_video(path, [_coded_frame(i) for i in range(N)], fps=25.0)
    return path


def test_describes_a_real_mp4(coded_mp4):
    clip = run_node(video, {"path": str(coded_mp4)})["video"]
    assert (clip.start, clip.stop, clip.n_frames) == (0, N, N)
    assert (clip.width, clip.height) == (W, H)
    assert clip.fps == pytest.approx(25.0)
    assert clip.sha256 == hash_file(coded_mp4)
    frames = list(iter_frames(clip))
    assert [i for i, _ in frames] == list(range(N))
    assert [_decode(f) for _, f in frames] == list(range(N))
    assert all(f.shape == (H, W, 3) and f.dtype == np.uint8 for _, f in frames)


def test_range_and_downscale(coded_mp4):
    clip = run_node(video, {"path": str(coded_mp4), "start": 5, "stop": 12, "scale": 0.5})["video"]
    assert (clip.start, clip.stop, clip.width, clip.height) == (5, 12, W // 2, H // 2)
    frames = list(iter_frames(clip))
    assert [i for i, _ in frames] == list(range(5, 12))
    assert [_decode(f) for _, f in frames] == list(range(5, 12))  # seeking lands on the right frame
    assert frames[0][1].shape == (H // 2, W // 2, 3)
    # a stop beyond the end is clamped to the end
    assert run_node(video, {"path": str(coded_mp4), "stop": 1000})["video"].stop == N


def _set_display_rotation(path, matrix) -> None:
    """Write an MP4's display matrix (its track header's 3x3 transformation, as a phone filming upright in portrait
    writes it) in place: ``matrix`` the nine 32-bit fixed-point values of ISO/IEC 14496-12's ``tkhd``."""
    import struct

    data = bytearray(path.read_bytes())
    at = data.find(b"tkhd")
    version = data[at + 4]
    # after the box type: version/flags 4, times 8 or 16, track id 4, reserved 4, duration 4 or 8, reserved 8,
    # layer 2, alternate group 2, volume 2, reserved 2
    off = at + 4 + 4 + (8 if version == 0 else 16) + 4 + 4 + (4 if version == 0 else 8) + 8 + 2 + 2 + 2 + 2
    data[off:off + 36] = struct.pack(">9i", *matrix)
    path.write_bytes(data)


def test_a_phone_video_filmed_in_portrait_is_read_upright(tmp_path):
    # a phone stores portrait video as landscape pixels plus a display rotation; the frames must come out as the
    # phone shows them (here: turned 90 degrees clockwise), with the size reported to match, or every pixel
    # position downstream (tracks, camera centre, overlay) is in a frame lying on its side
    img = np.full((H, W, 3), 255, np.uint8)
    img[:16, :16] = (0, 0, 255)  # red in the stored frame's top-left corner
    path = tmp_path / "portrait.mp4"
    write_video(path, [img] * 6, fps=25.0)
    _set_display_rotation(path, (0, 1 << 16, 0, -(1 << 16), 0, 0, 0, 0, 1 << 30))
    clip = run_node(video, {"path": str(path)})["video"]
    assert (clip.width, clip.height, clip.n_frames) == (H, W, 6)
    upright = np.rot90(img, k=-1)
    for _, f in iter_frames(clip):
        assert f.shape == (W, H, 3)
        assert np.abs(f.astype(int) - upright).mean() < 4.0  # codec noise only
    assert all(f.shape == (W, H, 3) for _, f in iter_frames_at(clip, [1, 4]))  # after a seek too


@pytest.mark.parametrize("gap", [0, 3, 100])
def test_frames_at_given_indices_are_the_streamed_ones(coded_mp4, monkeypatch, gap):
    """iter_frames_at (the room's background samples): the frames iter_frames gives at those indices, whether reached
    by decoding through (gaps up to SEEK_GAP) or by seeking; indices must be sorted and inside the clip."""
    monkeypatch.setattr(video_module, "SEEK_GAP", gap)  # 0: every frame seeked, 100: decoded through
    clip = run_node(video, {"path": str(coded_mp4), "start": 2, "stop": 22, "scale": 0.5})["video"]
    streamed = dict(iter_frames(clip))
    picks = [2, 3, 7, 8, 15, 21]
    got = list(iter_frames_at(clip, picks))
    assert [i for i, _ in got] == picks and [_decode(f) for _, f in got] == picks
    for i, f in got:
        np.testing.assert_array_equal(f, streamed[i])
    for bad in ([3, 2], [1, 5], [5, 22]):
        with pytest.raises(ValueError, match="sorted, unique and within 2..21"):
            list(iter_frames_at(clip, bad))

def test_missing_path_names_the_file(tmp_path):
    path = tmp_path / "nope.mp4"
    with pytest.raises(NodeError, match="nope.mp4.*does not exist"):
        run_node(video, {"path": str(path)})


def test_text_file_named_mp4_names_the_file(tmp_path):
    path = tmp_path / "notes.mp4"
    path.write_text("this is not a video\n")
    with pytest.raises(NodeError, match="notes.mp4"):
        run_node(video, {"path": str(path)})


@pytest.mark.parametrize("name, fourcc, message", [("empty.mp4", "mp4v", "cannot open"), ("empty.avi", "MJPG", "has no frames")])
def test_zero_frame_video_names_the_file(tmp_path, name, fourcc, message):
    path = tmp_path / name
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 30.0, (W, H))
    wr.release()  # no frames written (an mp4 is then unreadable, an AVI readable but empty)
    assert path.exists()
    with pytest.raises(NodeError, match=rf"{name}.*{message}"):
        run_node(video, {"path": str(path)})


def test_start_beyond_end(coded_mp4):
    with pytest.raises(NodeError, match=rf"start frame 30 is beyond the end.*{N} frames"):
        run_node(video, {"path": str(coded_mp4), "start": 30})


def test_bad_params_refused(coded_mp4):
    with pytest.raises(ValidationError, match=r"stop \(5\) must be greater than start \(5\)"):
        run_node(video, {"path": str(coded_mp4), "start": 5, "stop": 5})
    with pytest.raises(ValidationError, match=r"scale\n  Input should be less than or equal to 1"):
        run_node(video, {"path": str(coded_mp4), "scale": 1.5})


def test_decoding_failure_names_the_frame(tmp_path):
    # an AVI cut in half: its header still announces every frame, decoding stops in the middle
    full = tmp_path / "full.avi"
    wr = cv2.VideoWriter(str(full), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (W, H))
    rng = np.random.default_rng(0)
    for _ in range(20):
        wr.write(rng.integers(0, 256, (H, W, 3), dtype=np.uint8))
    wr.release()
    cut = tmp_path / "cut.avi"
    data = full.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    clip = run_node(video, {"path": str(cut)})["video"]
    assert clip.n_frames == 20
    seen = []
    # OpenCV would decode the frame the cut runs through, damaged, without a word: the AVI's chunk sizes tell
    with pytest.raises(NodeError, match=r"cut.avi: the file ends inside frame (\d+)'s data") as e:
        for i, _ in iter_frames(clip):
            seen.append(i)
    assert f"frame {len(seen)}'s data" in str(e.value) and 0 < len(seen) < 20
    assert avi_cut_frame(cut) == len(seen) and avi_cut_frame(full) is None
    assert f"set io.video 'stop' to {len(seen)}" in str(e.value)
    with pytest.raises(NodeError, match=r"cut.avi: the file ends inside frame \d+'s data \(on the way to frame 19\)"):
        list(iter_frames_at(clip, [0, 19]))  # decoded through: the first frame that fails is named
    # the frames before the cut are whole: a clip that stops there reads without an error
    short = run_node(video, {"path": str(cut), "stop": len(seen)})["video"]
    assert [i for i, _ in iter_frames(short)] == seen


def _timed_mp4(path, pts_600ths, codec="libx264"):
    """An MP4 whose frame ``i`` (stripe-coded with ``i``) is shown at ``pts_600ths[i] / 600`` s, as a phone's
    variable frame rate writes it (libx264: B-frames, so the file also has a ``ctts`` table)."""
    from fractions import Fraction

    av = pytest.importorskip("av")
    with av.open(str(path), "w") as c:
        s = c.add_stream(codec, rate=30)
        s.width, s.height, s.pix_fmt = W, H, "yuv420p"
        s.codec_context.time_base = s.time_base = Fraction(1, 600)
        for i, t in enumerate(pts_600ths):
            frame = av.VideoFrame.from_ndarray(_coded_frame(i)[..., ::-1].copy(), format="rgb24")
            frame.pts, frame.time_base = int(t), Fraction(1, 600)
            for packet in s.encode(frame):
                c.mux(packet)
        for packet in s.encode():
            c.mux(packet)
    return path


def _io_video_warnings(path, **params) -> list[str]:
    from tbha_graph.core.node import Context

    ctx = Context("decode", video.params.model_validate({"path": str(path), **params}))
    video.fn(ctx, None)
    return ctx.warnings


def test_a_phone_video_with_a_variable_frame_rate_is_flagged(tmp_path):
    """Phones drop to fewer frames a second in dim light; the capture spaces frames evenly at the file's average
    rate, so io.video reads the frame times from the MP4's index and says so, with the command that fixes it."""
    from tbha_graph.mocap.io.mp4_times import frame_times

    steps = [20] * 20 + [30] * 10 + [20] * 19  # 30 fps, a third of a second at 20 fps, 30 fps again
    pts = np.concatenate([[0], np.cumsum(steps)])
    path = _timed_mp4(tmp_path / "phone.mp4", pts)
    assert np.allclose(frame_times(path), pts / 600)  # showing order, B-frames reordered
    assert [_decode(f) for _, f in iter_frames(run_node(video, {"path": str(path)})["video"])] == list(range(50))
    (warning,) = _io_video_warnings(path)
    assert "frame times are uneven" in warning and "10 of 49 intervals" in warning and "33.3 ms" in warning
    assert "(33.3-50.0 ms)" in warning and "missing frame" not in warning
    assert "ffmpeg -i phone.mp4 -vf fps=30 -c:v libx264 -crf 18 phone_cfr.mp4" in warning
    assert _io_video_warnings(path, stop=20) == []  # the frames used are evenly spaced
    assert _io_video_warnings(path, start=31) == []


def test_a_dropped_frame_is_flagged_and_an_even_video_is_not(tmp_path, coded_mp4):
    from tbha_graph.mocap.io.mp4_times import frame_times

    pts = 20 * np.array([i if i < 25 else i + 1 for i in range(40)])  # the 26th frame's moment has no frame
    path = _timed_mp4(tmp_path / "dropped.mp4", pts)
    (warning,) = _io_video_warnings(path)
    assert "1 of 39 intervals" in warning and "1 frame(s) follow a gap of a missing frame or more (frame 25)" in warning
    even = _timed_mp4(tmp_path / "even.mp4", 20 * np.arange(40))
    assert np.allclose(np.diff(frame_times(even)), 1 / 30) and _io_video_warnings(even) == []
    assert _io_video_warnings(coded_mp4) == []  # OpenCV's own mp4v file (stts only)


def test_frame_times_of_files_without_an_mp4_index_are_none(tmp_path, coded_mp4):
    """An AVI, a cut MP4 (its index, written last, missing) or a damaged one: no times, no error."""
    from tbha_graph.mocap.io.mp4_times import frame_times

    avi = tmp_path / "take.avi"
    write_video(avi, [_coded_frame(i) for i in range(5)], fps=25.0)
    assert frame_times(avi) is None
    data = coded_mp4.read_bytes()
    assert frame_times(coded_mp4) is not None
    for i, cut in enumerate((len(data) // 2, len(data) - 40, 12)):
        (tmp_path / f"cut{i}.mp4").write_bytes(data[:cut])
        assert frame_times(tmp_path / f"cut{i}.mp4") is None
    at = data.find(b"stts")
    damaged = bytearray(data)
    damaged[at + 8: at + 12] = (10 ** 6).to_bytes(4, "big")  # an entry count the box cannot hold
    (tmp_path / "damaged.mp4").write_bytes(bytes(damaged))
    assert frame_times(tmp_path / "damaged.mp4") is None
