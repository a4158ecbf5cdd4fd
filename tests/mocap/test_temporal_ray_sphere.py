"""reconstruct.temporal_ray_sphere against the seed's frame-by-frame ray_sphere on the rendered sample's
ground truth (true camera and bones): with tracker-like 2D noise it must be far more accurate."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.reconstruct.ray_sphere import solve_ray_sphere
from tbha_graph.mocap.reconstruct.temporal_ray_sphere import choose_signs, temporal_ray_sphere
from tbha_graph.mocap.body import lengths_to_body

GT = Path(__file__).resolve().parents[2] / "data" / "sample" / "ground_truth.npz"


@pytest.fixture(scope="module")
def truth():
    with np.load(GT, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def mpjpe_mm(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1000)


def test_noisy_2d_temporal_beats_frame_by_frame(truth):
    cam = Camera(truth["K"], truth["R"], truth["t"], int(truth["width"]), int(truth["height"]))
    px = truth["joints2d"] + np.random.default_rng(0).normal(0, 0.7, truth["joints2d"].shape)
    n = px.shape[0]
    tracks = {"points": px, "tracked": np.ones((n, 16), bool), "fps": np.array(30.0),
              "width": np.array(cam.width), "height": np.array(cam.height)}
    out = run_node(temporal_ray_sphere, {}, tracks=tracks, camera=cam.to_model(), body=lengths_to_body(truth["bone_lengths"]))
    temporal = mpjpe_mm(out["motion"]["joints"], truth["joints3d_world"])
    seed, _ = solve_ray_sphere(px, cam, truth["bone_lengths"], continuity="velocity")
    frame_by_frame = mpjpe_mm(cam.to_world(seed), truth["joints3d_world"])
    print(f"0.7 px noise: temporal {temporal:.1f} mm, frame-by-frame {frame_by_frame:.1f} mm")
    assert temporal < 0.5 * frame_by_frame
    assert temporal < 120.0
    assert out["motion"]["tracked"].all() and "flips_left_ankle" in out["report"]


def test_sign_choice_follows_smooth_motion_through_tangency():
    t = np.linspace(-1, 1, 41)
    s_true = 0.3 * t  # a limb swinging through the plane perpendicular to its ray: the sign must flip once
    signs = choose_signs(np.abs(s_true), None, 0.0)
    assert np.allclose(signs * np.abs(s_true), s_true)
    away = 0.2 + 0.05 * np.sin(3 * t)  # always well in front of (or behind) the parent: never flips
    assert len(set(choose_signs(away, None, 0.0))) == 1
    # the anatomical cost decides where smoothness cannot: it forbids the + branch here
    cost = np.zeros((t.size, 2))
    cost[:, 0] = 1.0
    assert (choose_signs(away, cost, 10.0) == -1).all()


def test_pinned_side_changes_only_the_pinned_frames_and_draws_a_timeline(truth, tmp_path):
    from tbha_graph.mocap.skeleton import JOINT_INDEX
    from tbha_graph.mocap.viz.depth_sides import depth_sides

    cam = Camera(truth["K"], truth["R"], truth["t"], int(truth["width"]), int(truth["height"]))
    n = truth["joints2d"].shape[0]
    tracks = {"points": truth["joints2d"], "tracked": np.ones((n, 16), bool), "fps": np.array(30.0),
              "width": np.array(cam.width), "height": np.array(cam.height)}
    args = dict(tracks=tracks, camera=cam.to_model(), body=lengths_to_body(truth["bone_lengths"]))
    free = run_node(temporal_ray_sphere, {}, **args)
    j = JOINT_INDEX["left_wrist"]
    chosen = free["sides"]["sides"][100:121, j]
    flip = "front" if chosen[0] > 0 else "back"  # the other side than the solver chose at frame 100
    pinned = run_node(temporal_ray_sphere, {"overrides": [{"joint": "left_wrist", "frames": [100, 120], "side": flip}]}, **args)
    want = -1 if flip == "front" else 1
    assert (pinned["sides"]["sides"][100:121, j] == want).all()
    moved = np.linalg.norm(pinned["motion"]["joints"] - free["motion"]["joints"], axis=-1)  # (n, 16)
    outside = np.ones(n, bool)
    outside[100:121] = False
    assert moved[outside].max() < 1e-9  # nothing else changes
    assert moved[100:121, j].max() > 0.01
    png = run_node(depth_sides, {}, sides=pinned["sides"])["png"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_pin_is_refused_with_the_joint_names():
    with pytest.raises(ValidationError, match=r"overrides\.0\.joint\n  Value error, 'left_wirst' is not a limb or head joint \(did you mean 'left_wrist'\?\)"):
        run_node(temporal_ray_sphere, {"overrides": [{"joint": "left_wirst", "frames": [1, 2], "side": "front"}]})
