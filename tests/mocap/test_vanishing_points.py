"""calibrate.vanishing_points: the focal length from a room's perpendicular lines, or none (and why)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tbha_graph.mocap.bundles.video import VideoClip
from tbha_graph.mocap.calibrate.vanishing_points import VanishingParams, estimate_focal, median_background
from tbha_graph.mocap.camera import Camera

ROOT = Path(__file__).resolve().parents[2]


def tiled_floor(eye, target, focal_px: float, width: int = 640, height: int = 480, tile: float = 0.5,
                roll_deg: float = 0.0) -> np.ndarray:
    """A grey image of a floor (y = 0) tiled in ``tile`` m squares, seen by a camera at ``eye`` looking at ``target``,
    rolled by ``roll_deg`` about its axis."""
    up = (np.sin(np.radians(roll_deg)), np.cos(np.radians(roll_deg)), 0.0)
    cam = Camera.look_at(eye, target, focal_px=focal_px, width=width, height=height, up=up)
    img = np.full((height, width, 3), 120, np.uint8)
    ticks = np.arange(-6.0, 6.0 + 1e-9, tile)
    lines = [((x, 0.0, -6.0), (x, 0.0, 6.0)) for x in ticks] + [((-6.0, 0.0, z), (6.0, 0.0, z)) for z in ticks]
    for a, b in lines:
        s = np.linspace(0.0, 1.0, 400)[:, None]
        pts = np.asarray(a) * (1 - s) + np.asarray(b) * s
        front = cam.to_camera(pts)[:, 2] > 0.3  # only what lies in front of the camera
        uv = cam.project(pts[front])
        if len(uv) > 1:
            cv2.polylines(img, [np.round(uv * 16).astype(np.int32)], False, (40, 40, 40), 2, cv2.LINE_AA, shift=4)
    return img


def sample_clip() -> VideoClip:
    """The bundled sample video as a clip (640x480, 30 fps, every frame)."""
    path = ROOT / "data" / "sample" / "sample.mp4"
    cap = cv2.VideoCapture(str(path))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    cap.release()
    return VideoClip(path=str(path), sha256="-", stop=n, fps=30.0, width=640, height=480)


@pytest.mark.parametrize("focal, eye, roll, bound", [(500.0, (-1.0, 0.9, 5.0), 0.0, 0.8), (800.0, (2.0, 1.5, 6.0), 0.0, 1.1),
                                                (1200.0, (1.5, 1.0, 4.0), 0.0, 1.3), (1200.0, (1.5, 1.0, 4.0), 5.0, 2.4)])
def test_focal_from_an_oblique_tiled_floor(focal, eye, roll, bound):
    """Measured +0.46, +0.71, -0.82 % level, and -1.61 % rolled 5° (the level-horizon prior, 1°, yields to the lines)."""
    found = estimate_focal(tiled_floor(eye, (0.0, 0.5, 0.0), focal, roll_deg=roll), VanishingParams())
    assert found["focal_px"] is not None and found["level_floor"], found
    assert abs(found["focal_px"] / focal - 1.0) * 100 < bound, found
    assert found["focal_sd_pct"] is not None and found["focal_sd_pct"] < 2.4


def test_no_focal_from_a_plain_background_or_a_room_seen_square_on():
    plain = estimate_focal(np.full((480, 640, 3), 128, np.uint8), VanishingParams())
    assert plain["focal_px"] is None and "too few" in plain["reason"]
    # looking straight down the tiles: the sideways lines stay parallel in the image (no second vanishing point)
    square = estimate_focal(tiled_floor((0.0, 1.2, 6.0), (0.0, 0.5, 0.0), 700.0), VanishingParams())
    assert square["focal_px"] is None and "perpendicular" in square["reason"], square


def test_the_sample_room_gives_its_focal_length():
    """The bundled sample (true focal 700 px): within 0.45 % (measured +0.30 %, sd 0.8 %)."""
    found = estimate_focal(median_background(sample_clip(), 25), VanishingParams())
    assert abs(found["focal_px"] / 700.0 - 1.0) < 0.0045, found
    assert found["focal_sd_pct"] < 1.2


def test_a_plain_room_gives_no_lens_and_a_warning_the_run_reports(tmp_path):
    """Through the framework: the node's warning reaches the run (and so metrics.json and the summary), the lens
    is empty (the solver then falls back on the take) and the picture says why."""
    from tbha_graph.core.cache import Cache
    from tbha_graph.core.runner import load_graph, run_graph

    video = tmp_path / "plain.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (320, 240))
    for k in range(12):  # a grey wall and a blob moving across it
        frame = np.full((240, 320, 3), 128, np.uint8)
        cv2.circle(frame, (40 + 20 * k, 120), 15, (200, 200, 200), -1)
        writer.write(frame)
    writer.release()
    spec = tmp_path / "p.yaml"
    spec.write_text(f"nodes:\n  decode: {{type: io.video, params: {{path: {video}}}}}\n"
                    "  lens: {type: calibrate.vanishing_points, inputs: {video: decode.video}}\n"
                    "outputs: {room_lines.png: lens.picture}\n")
    run = run_graph(load_graph(spec), out_dir=tmp_path / "run", cache=Cache(tmp_path / "cache"))
    lens = run.output("lens.lens")
    assert lens.focal_px is None and "too few" in lens.source
    assert any(w["node"] == "lens" and "no focal length from the room" in w["message"] for w in run.node_warnings())
    assert cv2.imread(str(tmp_path / "run" / "room_lines.png")).shape == (240, 320, 3)


def test_the_background_frames_go_through_progress_and_an_interrupted_run_stops():
    """The room's background is read frame by frame through ``progress`` (a bar on a long take); with the run's
    cancel event set (Ctrl-C under ``tbha-run --jobs 2``) the bootstrap stops at its next resample."""
    import threading

    from tbha_graph.core.node import CANCEL, Cancelled

    clip = sample_clip()
    seen = []

    def progress(items, total=None, desc=""):
        seen.append((total, desc))
        yield from items

    background = median_background(clip, 5, progress)
    assert seen == [(5, "room background")] and background.shape == (480, 640, 3)
    image = tiled_floor((-1.0, 0.9, 5.0), (0.0, 0.5, 0.0), 500.0)
    event = threading.Event()
    event.set()
    token = CANCEL.set(event)
    try:
        with pytest.raises(Cancelled):
            estimate_focal(image, VanishingParams())
    finally:
        CANCEL.reset(token)
    assert estimate_focal(image, VanishingParams())["focal_px"] is not None  # the same call without the event runs
