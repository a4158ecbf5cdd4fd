"""MediaPipe's own info and warning lines (written by C++ straight to descriptor 2) kept off the terminal while
everything else written there passes: the filter on its own with lines written at the descriptor, and real
MediaPipe through the node."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.detect.native_log import SHOW_ENV, chatter_start, filtered_stderr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_keypoints import require_mediapipe  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[2] / "data" / "sample" / "sample.mp4"

# lines as MediaPipe 0.10.21 writes them (absl before its initialisation puts the epoch seconds in the time field)
CHATTER = [
    b"INFO: Created TensorFlow Lite XNNPACK delegate for CPU.",
    b"WARNING: All log messages before absl::InitializeLog() is called are written to STDERR",
    b"W0000 00:00:1795938554.244213   25805 inference_feedback_manager.cc:114] Feedback manager requires a model with "
    b"a single signature inference. Disabling support for feedback tensors.",
    b"W0000 00:00:1795938554.753072   25803 landmark_projection_calculator.cc:186] Using NORM_RECT without "
    b"IMAGE_DIMENSIONS is only supported for the square ROI.",
    b"I1129 08:12:33.123456   4242 gl_context.cc:357] GL version: 3.2",
]
KEPT = [
    b"E0000 00:00:1795938554.753072   25803 calculator_graph.cc:887] INTERNAL: a real failure",
    b"F1129 08:12:33.123456   4242 pose.cc:1] fatal",
    b"  ran     detect                 detect.mediapipe_pose             23.61 s",
    b"WARNING: something else",
    b"INFO: something else",
    b"W 12 not an absl line",
]


def test_chatter_lines_are_recognised_and_nothing_else():
    assert all(chatter_start(line) == 0 for line in CHATTER)
    assert not any(chatter_start(line) is not None for line in KEPT)
    assert chatter_start(b"detect  40%" + CHATTER[2]) == len(b"detect  40%")  # after a progress bar's unended line


def test_the_filter_drops_the_chatter_and_passes_the_rest_progress_bars_included(capfd, monkeypatch):
    monkeypatch.delenv(SHOW_ENV, raising=False)
    with filtered_stderr() as hidden:
        for line in CHATTER[:2] + KEPT[:3] + CHATTER[2:] + KEPT[3:]:
            os.write(2, line + b"\n")
        os.write(2, b"\rdetect  40%")  # a progress bar's line, not ended: passes at once
        with filtered_stderr():  # nested: the same filter
            os.write(2, CHATTER[2] + b"\n")
        os.write(2, b"a line of this program's own\n")  # (print to sys.stderr: pytest's capture object, not descriptor 2)
    os.write(2, CHATTER[2] + b"\n")  # the filter is gone: descriptor 2 is the real one again
    err = capfd.readouterr().err.encode()
    assert hidden[0] == len(CHATTER) + 1  # the outermost block counts them all (an inner one: what was read by then)
    for line in KEPT:
        assert line + b"\n" in err
    assert b"\rdetect  40%" in err
    assert b"a line of this program's own\n" in err
    assert err.count(b"inference_feedback_manager") == 1 and b"XNNPACK" not in err and b"gl_context" not in err


def test_the_environment_variable_shows_every_line(capfd, monkeypatch):
    monkeypatch.setenv(SHOW_ENV, "1")
    with filtered_stderr() as hidden:
        os.write(2, CHATTER[2] + b"\n")
    assert hidden[0] == 0 and CHATTER[2] in capfd.readouterr().err.encode()


def test_real_mediapipe_leaves_no_lines_of_its_own(capfd, monkeypatch):
    require_mediapipe()
    from tbha_graph.mocap.detect.mediapipe_pose import mediapipe_pose
    from tbha_graph.mocap.io.video import probe_video

    monkeypatch.delenv(SHOW_ENV, raising=False)
    out = run_node(mediapipe_pose, {"threads": 2}, video=probe_video(SAMPLE, stop=40))
    err = capfd.readouterr().err
    assert out["report"]["frames_detected"] == 40 and np.isfinite(out["tracks"]["points"]).all()
    assert "inference_feedback_manager" not in err and "XNNPACK" not in err, err
    # with the variable set, MediaPipe's lines reach the terminal as they are
    monkeypatch.setenv(SHOW_ENV, "1")
    run_node(mediapipe_pose, {"threads": 1}, video=probe_video(SAMPLE, stop=2))
    assert "inference_feedback_manager" in capfd.readouterr().err
