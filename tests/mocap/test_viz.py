"""viz.overlay, viz.error_plot, viz.skeleton_sheet on CMU 131_02 seen by a known camera."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.evaluate.metrics import metrics
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh
from tbha_graph.mocap.io.video import probe_video
from tbha_graph.mocap.io.video_writer import open_video_writer
from tbha_graph.mocap.viz import draw, style
from tbha_graph.mocap.viz.error_plot import error_plot
from tbha_graph.mocap.viz.overlay import OverlayLayers, draw_overlay, overlay
from tbha_graph.mocap.viz.skeleton_sheet import posture, skeleton_sheet

CLIP = Path(__file__).resolve().parents[2] / "data" / "mocap" / "cmu" / "131_02.bvh"
N, FPS, W, H = 16, 30.0, 320, 240
BACKGROUND = 90
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
HEAD = sk.JOINT_INDEX["head"]  # lost in frames 0..7, tracked from frame 8 (nothing is drawn above it)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    joints = motion16_from_bvh(CLIP)["joints"][: 4 * N : 4]
    cam = Camera.look_at((0.3, 1.0, 4.0), (0.3, 0.8, -1.0), focal_px=400.0, width=W, height=H)
    path = tmp_path_factory.mktemp("video") / "grey.mp4"
    with open_video_writer(path, FPS, W, H, codec="mp4v") as w:
        for _ in range(N):
            w.write(np.full((H, W, 3), BACKGROUND, np.uint8))
    pts = cam.project(joints)
    tracked = np.ones((N, sk.N_JOINTS), dtype=bool)
    tracked[:8, HEAD] = False
    tracks = {"points": pts, "tracked": tracked, "fps": np.array(FPS), "width": np.array(W), "height": np.array(H)}
    truth = {"joints3d_world": joints, "joints2d": pts, "fps": np.array(FPS), "width": np.array(W), "height": np.array(H)}
    return {"clip": probe_video(path), "joints": joints, "camera": cam, "tracks": tracks, "truth": truth}


def outward(points, j):
    """Unit 2D direction from joint j's parent to j (pointing away from the bone, beyond a leaf joint)."""
    d = points[j] - points[sk.PARENTS[j]]
    return d / np.linalg.norm(d)


def near(pixel, bgr, tol):
    return int(np.abs(pixel.astype(int) - np.array(bgr)).max()) <= tol


def read_video(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    cap.release()
    return frames


def greenish(img):
    """Pixels whose green clearly dominates (thin green lines lose saturation in H.264's 4:2:0 chroma)."""
    i = img.astype(int)
    return int(((i[..., 1] > i[..., 2] + 30) & (i[..., 1] > i[..., 0] + 30)).sum())


def color_pixels(img, bgr, tol=12):
    return int((np.abs(img.astype(int) - np.array(bgr)).max(axis=-1) <= tol).sum())


# --- viz.overlay ------------------------------------------------------------------------------------
def test_draw_overlay_filled_dots_for_tracked_hollow_for_lost(scene):
    layers = OverlayLayers(N, scene["clip"], scene["tracks"], None, None, None, True)
    sizes = draw.Sizes(dot=8, line=2, font=0.4)
    for i, lost in ((3, True), (10, False)):
        frame = draw_overlay(np.full((H, W, 3), BACKGROUND, np.uint8), i, layers, sizes)
        pts = scene["tracks"]["points"][i]
        inside = np.rint(pts[HEAD] + 4 * outward(pts, HEAD)).astype(int)
        ring = np.rint(pts[HEAD] + 8 * outward(pts, HEAD)).astype(int)
        assert tuple(frame[inside[1], inside[0]]) == ((BACKGROUND,) * 3 if lost else style.TRACKS_BGR)
        assert near(frame[ring[1], ring[0]], style.TRACKS_BGR, 60)


def test_lost_joint_drawn_where_the_3d_puts_it_never_at_an_off_body_prediction(scene):
    """A lost joint's ring goes at the motion's reprojection, not at the tracker's prediction, and no track
    bone reaches it (issue 13: a lost joint is never shown off the body)."""
    tracks = dict(scene["tracks"], points=scene["tracks"]["points"].copy())
    i = 3  # head lost
    pts = scene["tracks"]["points"][i]
    off = pts[HEAD] + np.array([60.0, -20.0])  # the tracker's prediction, off the body
    tracks["points"][i, HEAD] = off
    layers = OverlayLayers(N, scene["clip"], tracks, {"joints": scene["joints"], "fps": np.array(FPS)},
                           scene["camera"].to_model(), None, True)
    sizes = draw.Sizes(dot=8, line=2, font=0.4)
    frame = draw_overlay(np.full((H, W, 3), BACKGROUND, np.uint8), i, layers, sizes)
    ring = np.rint(pts[HEAD] + 8 * outward(pts, HEAD)).astype(int)  # on the reprojected head's ring
    assert near(frame[ring[1], ring[0]], style.TRACKS_BGR, 60)
    u, v = np.rint(off).astype(int)
    patch = frame[v - 10:v + 11, u - 10:u + 11]
    assert color_pixels(patch, style.TRACKS_BGR, 60) == 0  # nothing yellow where the tracker guessed
    mid = np.rint((off + pts[sk.PARENTS[HEAD]]) / 2).astype(int)  # nor a bone towards it
    assert color_pixels(frame[mid[1] - 2:mid[1] + 3, mid[0] - 2:mid[0] + 3], style.TRACKS_BGR, 60) == 0
    assert "where the 3D puts it" in layers.legend()[1][1]


def test_overlay_video_has_the_clip_frames_size_and_colours(scene, tmp_path):
    motion = {"joints": scene["joints"] + np.array([0.4, 0.0, 0.0]), "fps": np.array(FPS)}  # reprojection beside the tracks
    out = run_node(overlay, work_dir=tmp_path, params={"dot_radius": 6, "line_width": 2}, video=scene["clip"], tracks=scene["tracks"],
                   motion=motion, camera=scene["camera"].to_model(), truth=scene["truth"])
    frames = read_video(out["video"])
    assert len(frames) == N and frames[0].shape == (H, W, 3)
    cap = cv2.VideoCapture(str(out["video"]))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(FPS)
    cap.release()
    i = 7
    assert color_pixels(frames[i], style.REPROJECTED_BGR, 40) > 100  # the magenta reprojected skeleton is drawn
    assert greenish(frames[i][130:]) > 100  # truth crosses on the legs (below the legend)
    # tracks only: no magenta, no green; filled dots for tracked joints, hollow circles for lost ones
    plain = read_video(run_node(overlay, work_dir=tmp_path / "plain", params={"dot_radius": 6}, video=scene["clip"],
                                tracks=scene["tracks"])["video"])
    assert len(plain) == N
    assert color_pixels(plain[i], style.REPROJECTED_BGR, 40) == 0 and greenish(plain[i]) == 0
    for i, lost in ((4, True), (12, False)):
        pts = scene["tracks"]["points"][i]
        inside = np.rint(pts[HEAD] + 3 * outward(pts, HEAD)).astype(int)
        if lost:  # hollow circle: background inside
            assert near(plain[i][inside[1], inside[0]], (BACKGROUND,) * 3, 30)
        else:  # filled dot, its colour survives H.264
            assert near(plain[i][inside[1], inside[0]], style.TRACKS_BGR, 45)


def test_overlay_refuses_mismatched_inputs(scene, tmp_path):
    short = {k: (v[:-1] if k in ("points", "tracked") else v) for k, v in scene["tracks"].items()}
    with pytest.raises(NodeError, match=f"video clip has {N} frames"):
        run_node(overlay, work_dir=tmp_path, video=scene["clip"], tracks=short)
    with pytest.raises(NodeError, match="only one of them is connected"):
        run_node(overlay, work_dir=tmp_path, video=scene["clip"], tracks=scene["tracks"],
                 motion={"joints": scene["joints"], "fps": np.array(FPS)})
    assert not list(tmp_path.glob("*.mp4"))


# --- PNGs ------------------------------------------------------------------------------------------
def _png(path):
    assert Path(path).read_bytes()[:8] == PNG_SIGNATURE
    img = cv2.imread(str(path))
    assert img is not None and img.shape[0] > 200 and img.shape[1] > 400
    return img


def _errors(scene, truth):
    rng = np.random.default_rng(0)
    tracks = dict(scene["tracks"], points=scene["tracks"]["points"] + rng.normal(0, 1.0, (N, 16, 2)))
    motion = {"joints": scene["joints"] + rng.normal(0, 0.02, scene["joints"].shape), "fps": np.array(FPS)}
    return run_node(metrics, motion=motion, tracks=tracks, camera=scene["camera"].to_model(), truth=truth)["errors"]


def test_error_plot_draws_3d_curves_only_with_ground_truth(scene, tmp_path):
    with_gt = _png(run_node(error_plot, work_dir=tmp_path / "a", errors=_errors(scene, scene["truth"]))["png"])
    without = _png(run_node(error_plot, work_dir=tmp_path / "b", errors=_errors(scene, {}))["png"])
    assert color_pixels(with_gt, style.ERROR3D_BGR) > 200 and color_pixels(without, style.ERROR3D_BGR) == 0
    assert color_pixels(with_gt, style.TRACKS_PLOT_BGR) > 200 and color_pixels(without, style.TRACKS_PLOT_BGR) == 0
    assert color_pixels(without, style.REPROJECTED_BGR) > 200
    assert with_gt.shape[0] > without.shape[0]  # two panels vs one


def test_skeleton_sheet_png_and_posture(scene, tmp_path):
    motion = {"joints": scene["joints"], "fps": np.array(FPS)}
    img = _png(run_node(skeleton_sheet, work_dir=tmp_path, params={"frames": 4}, motion=motion)["png"])
    assert color_pixels(img, style.LEFT_BGR, 20) > 100 and color_pixels(img, style.RIGHT_BGR, 20) > 100
    lean, heading, _ = posture(scene["joints"])
    assert (lean < 25).all() and (np.abs(heading) < 35).all()  # CMU walk: upright, towards +z
    turned = scene["joints"] * np.array([-1.0, 1.0, -1.0])  # turned 180 degrees about y
    assert (np.abs(posture(turned)[1]) > 145).all()
    upside_down = scene["joints"] * np.array([1.0, -1.0, -1.0])  # rotated 180 degrees about x
    assert (posture(upside_down)[0] > 155).all()
    with pytest.raises(NodeError, match="no joint position is finite"):
        run_node(skeleton_sheet, work_dir=tmp_path, motion={"joints": np.full((3, 16, 3), np.nan), "fps": np.array(FPS)})
