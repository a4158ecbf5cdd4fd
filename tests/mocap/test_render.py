"""Tests of the tight-suit renderer (synth.render_suit_video), synth.camera and synth.tpose_lead_in.

Renders are a handful of frames at small sizes, so the whole file runs in a few seconds.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.suit import load_suit
from tbha_graph.mocap.synth.camera import camera as camera_node
from tbha_graph.mocap.synth.render_suit_video import render_suit_video
from tbha_graph.mocap.synth.tpose_lead_in import tpose_lead_in

ROOT = Path(__file__).resolve().parents[2]
BVH = ROOT / "data" / "mocap" / "cmu" / "131_02.bvh"
J = sk.JOINT_INDEX
CLEAN = {"noise_sigma": 0.0, "exposure_jitter": 0.0}  # exact colours for pixel checks


def standing_tpose() -> np.ndarray:
    """T-pose (16, 3) metres with the ankles 8 cm above the floor."""
    pose = sk.tpose()
    pose[:, 1] += 0.08 - pose[J["left_ankle"], 1]
    return pose


def front_camera(width: int, height: int, focal: float) -> Camera:
    return Camera.look_at((0.0, 1.2, 4.0), (0.0, 1.0, 0.0), focal_px=focal, width=width, height=height)


def render(tmp_path: Path, joints: np.ndarray, cam: Camera, fps: float = 30.0, **params):
    p = {"width": cam.width, "height": cam.height, "fps": 30.0, **params}
    out = run_node(
        render_suit_video, p, work_dir=tmp_path,
        motion={"joints": np.asarray(joints, dtype=np.float64), "fps": np.array(fps)}, camera=cam.to_model(),
    )
    return out["video"], out["ground_truth"]


def read_frames(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    cap.release()
    return frames


def colour_mask(img: np.ndarray, rgb: np.ndarray, max_hue_deg: float = 14.0, min_sat: float = 0.3) -> np.ndarray:
    """Pixels of BGR ``img`` with the hue of ``rgb`` (3,) in [0, 1] and some saturation (hue survives
    the shading and the whitish specular highlights)."""
    hsv = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2HSV_FULL).astype(np.float64)
    ref = cv2.cvtColor(np.uint8([[np.rint(rgb[::-1] * 255)]]), cv2.COLOR_BGR2HSV_FULL)[0, 0].astype(np.float64)
    dh = np.abs(hsv[..., 0] - ref[0])
    dh = np.minimum(dh, 256.0 - dh) * 360.0 / 256.0
    return (dh < max_hue_deg) & (hsv[..., 1] > min_sat * 255)


# --------------------------------------------------------------------------------------------
def test_ground_truth_projects_the_rendered_joints(tmp_path):
    """Motion at 120 fps rendered at 30 fps: ground truth holds every 4th motion frame, projected by K, R, t."""
    base = standing_tpose()
    n = 9
    motion = np.repeat(base[None], n, axis=0)
    motion[:, :, 0] += np.linspace(0.0, 0.08, n)[:, None]  # slide sideways 8 cm over 8/120 s
    cam = front_camera(160, 120, 180.0)
    video, gt = render(tmp_path, motion, cam, fps=120.0, **CLEAN)
    assert gt["joints3d_world"].shape == (3, 16, 3)
    np.testing.assert_allclose(gt["joints3d_world"], motion[::4], atol=1e-12)
    np.testing.assert_allclose(gt["joints2d"], cam.project(motion[::4]), atol=1e-9)
    gcam = Camera(K=gt["K"], R=gt["R"], t=gt["t"], width=int(gt["width"]), height=int(gt["height"]))
    np.testing.assert_allclose(gt["joints2d"], gcam.project(gt["joints3d_world"]), atol=1e-9)
    np.testing.assert_allclose(gt["joints3d_cam"], gcam.to_camera(gt["joints3d_world"]), atol=1e-12)
    np.testing.assert_allclose(gt["patch2d"], gcam.project(gt["patch_centers_world"]), atol=1e-9)
    assert float(gt["fps"]) == 30.0 and list(gt["joint_names"]) == list(sk.JOINT_NAMES)
    assert load_suit().model_validate_json(str(gt["suit"])) == load_suit()
    np.testing.assert_allclose(gt["bone_lengths"], sk.measure_bone_lengths(base), atol=1e-9)


def test_patch_colours_are_drawn_where_the_ground_truth_says(tmp_path):
    """In a frontal T-pose every patch is visible, and the pixel at its projected centre has its colour."""
    cam = front_camera(320, 240, 420.0)
    video, gt = render(tmp_path, standing_tpose()[None], cam, **CLEAN)
    assert gt["patch_visible"].all()
    img = read_frames(video)[0]
    suit = load_suit()
    rgb = suit.patch_rgb()
    for p, name in enumerate(sk.PATCHED_JOINTS):
        u, v = np.rint(gt["patch2d"][0, p]).astype(int)
        window = img[v - 1 : v + 2, u - 1 : u + 2]
        assert colour_mask(window, rgb[p]).mean() > 0.5, f"{name}: patch colour not found at its centre"
    # the head is dark hair, no patch
    u, v = np.rint(gt["joints2d"][0, J["head"]] + [0, -4]).astype(int)
    assert img[v, u].astype(int).sum() < 3 * 90


def test_patch_behind_the_torso_is_hidden(tmp_path):
    """Left arm folded behind the back: its elbow and wrist patches are neither drawn nor marked visible."""
    pose = standing_tpose()
    sh = pose[J["left_shoulder"]]
    pose[J["left_elbow"]] = sh + np.array([-0.08, -0.2, -0.18])  # behind the back, within the torso's outline
    pose[J["left_wrist"]] = pose[J["left_elbow"]] + np.array([-0.1, -0.2, 0.0])
    cam = front_camera(320, 240, 420.0)
    video, gt = render(tmp_path, pose[None], cam, **CLEAN)
    vis = dict(zip(sk.PATCHED_JOINTS, gt["patch_visible"][0]))
    assert not vis["left_elbow"] and not vis["left_wrist"]
    assert vis["right_elbow"] and vis["right_wrist"] and vis["chest"]
    img = read_frames(video)[0]
    rgb = dict(zip(sk.PATCHED_JOINTS, load_suit().patch_rgb()))
    for name, seen in (("left_elbow", False), ("left_wrist", False), ("right_elbow", True), ("right_wrist", True)):
        u, v = np.rint(gt["joints2d"][0, J[name]]).astype(int)
        window = img[max(v - 8, 0) : v + 9, max(u - 8, 0) : u + 9]
        found = int(colour_mask(window, rgb[name]).sum())
        assert (found > 5) == seen, f"{name}: {found} pixels of its colour near its projection"


def test_video_reads_back_with_expected_frames_and_size(tmp_path):
    motion = np.repeat(standing_tpose()[None], 6, axis=0)
    cam = front_camera(96, 72, 110.0)
    video, gt = render(tmp_path, motion, cam)
    assert video.suffix == ".mp4" and video.is_file()
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == 96 and int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == 72
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(30.0)
    cap.release()
    frames = read_frames(video)
    assert len(frames) == 6 == gt["joints2d"].shape[0]
    assert all(f.shape == (72, 96, 3) for f in frames)
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir()), "temporary file left behind"


def test_same_seed_same_frames_other_seed_other_noise(tmp_path):
    motion = np.repeat(standing_tpose()[None], 3, axis=0)
    cam = front_camera(96, 72, 110.0)
    runs = {}
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        (tmp_path / name).mkdir()
        video, gt = render(tmp_path / name, motion, cam, seed=seed, noise_sigma=4.0)
        runs[name] = (np.stack(read_frames(video)), gt)
    a, b, c = runs["a"][0], runs["b"][0], runs["c"][0]
    assert np.array_equal(a, b)
    diff = np.abs(a.astype(int) - c.astype(int))
    assert diff.mean() > 1.0  # sensor noise (and exposure flicker) differ
    np.testing.assert_array_equal(runs["a"][1]["joints2d"], runs["c"][1]["joints2d"])
    assert not np.array_equal(a[0], a[1])  # a still pose, yet the noise differs frame to frame


def test_bad_motion_and_params_are_refused(tmp_path):
    cam = front_camera(96, 72, 110.0)
    motion = np.repeat(standing_tpose()[None], 3, axis=0)
    motion[2, 5] = np.nan
    with pytest.raises(NodeError, match="motion frame 2"):
        render(tmp_path, motion, cam)
    behind = np.repeat(standing_tpose()[None], 2, axis=0)
    behind[1, :, 2] += 5.0  # walks through the camera
    with pytest.raises(NodeError, match="video frame 1"):
        render(tmp_path, behind, cam)
    with pytest.raises(ValidationError):
        render(tmp_path, motion, cam, width=97)
    with pytest.raises(ValidationError):
        render(tmp_path, motion, cam, noise_sigma=-1.0)


def test_suit_port_camera_rescale_and_motion_blur(tmp_path):
    """A suit given on the port is drawn; a camera of another size is rescaled; motion blur smears a
    moving arm but leaves the ground truth at the frame time."""
    suit = load_suit()
    custom = suit.model_copy(update={"colors": {**suit.colors, "purple": "#20d040"}})  # chest patch now green
    pose = standing_tpose()
    small = front_camera(160, 120, 210.0)  # the video is twice as large
    out = run_node(
        render_suit_video, {"width": 320, "height": 240, **CLEAN}, work_dir=tmp_path,
        motion={"joints": pose[None], "fps": np.array(30.0)}, camera=small.to_model(), suit=custom,
    )
    gt = out["ground_truth"]
    assert (int(gt["width"]), int(gt["height"])) == (320, 240)
    np.testing.assert_allclose(gt["K"][0, 0], 420.0)
    np.testing.assert_allclose(gt["joints2d"][0], (small.project(pose) + 0.5) * 2 - 0.5, atol=1e-9)
    img = read_frames(out["video"])[0]
    u, v = np.rint(gt["patch2d"][0, sk.PATCHED_JOINTS.index("chest")]).astype(int)
    assert colour_mask(img[v - 1 : v + 2, u - 1 : u + 2], np.array([0x20, 0xD0, 0x40]) / 255).all()
    with pytest.raises(NodeError, match="suit"):
        run_node(render_suit_video, {"suit": str(ROOT / "tbha_graph" / "mocap" / "suit_default.yaml")},
                 work_dir=tmp_path, motion={"joints": pose[None], "fps": np.array(30.0)}, camera=small.to_model(), suit=custom)

    # the left arm sweeps down fast: with motion blur it covers more of the (plain) background, and
    # its wrist patch is smeared, so no pixel keeps the patch's full colour
    n = 5
    motion = np.repeat(pose[None], n, axis=0)
    sh = pose[J["left_shoulder"]]
    for i, ang in enumerate(np.linspace(0.0, 2.0, n)):
        for name in ("left_elbow", "left_wrist"):
            r = pose[J[name], 0] - sh[0]
            motion[i, J[name]] = sh + r * np.array([np.cos(ang), -np.sin(ang), 0.0])
    cam = front_camera(320, 240, 420.0)
    magenta = load_suit().patch_rgb()[sk.PATCHED_JOINTS.index("left_wrist")]
    counts, strong, gts = [], [], []
    for samples in (1, 5):
        (tmp_path / f"mb{samples}").mkdir()
        video, gt = render(tmp_path / f"mb{samples}", motion, cam, motion_blur_samples=samples, shutter=1.0,
                           background="plain", background_color="#808080", **CLEAN)
        frame = read_frames(video)[2].astype(int)
        counts.append(int((np.abs(frame - 128).sum(axis=-1) > 24).sum()))  # body pixels
        u, v = np.rint(gt["joints2d"][2, J["left_wrist"]]).astype(int)
        strong.append(int(colour_mask(frame[v - 30 : v + 31, u - 30 : u + 31].astype(np.uint8), magenta).sum()))
        gts.append(gt)
    assert counts[1] > counts[0] + 150, counts
    assert strong[0] > 20 and strong[1] < strong[0] / 2, strong
    for key in ("joints2d", "patch2d", "patch_visible"):
        np.testing.assert_array_equal(gts[0][key], gts[1][key])


def test_default_camera_frames_the_whole_body():
    cam = run_node(camera_node)["camera"].camera()
    assert (cam.width, cam.height) == (640, 480)
    assert cam.center[2] > 4.0 and cam.R[2] @ np.array([0.0, 0.0, -1.0]) > 0.9  # in front, looking at -z
    px = cam.project(standing_tpose())
    assert (px[:, 0] > 60).all() and (px[:, 0] < 580).all() and (px[:, 1] > 60).all() and (px[:, 1] < 420).all()
    with pytest.raises(ValidationError):
        run_node(camera_node, {"eye": [0, 1, 0], "target": [0, 1, 0]})


# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lead_in():
    if not BVH.is_file():
        pytest.skip(f"{BVH} missing")
    params = {"path": str(BVH), "hold_seconds": 0.5, "blend_seconds": 0.5, "duration": 1.5}
    return run_node(tpose_lead_in, params)["motion"]


def test_lead_in_starts_in_a_tpose_facing_plus_z(lead_in):
    joints, fps = lead_in["joints"], float(lead_in["fps"])
    assert fps == pytest.approx(120.0, rel=1e-4)
    assert joints.shape[0] == round(0.5 * fps) + round(1.5 * fps) + 1
    first = joints[0]
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
            d = unit(first[J[f"{side}_{b}"]] - first[J[f"{side}_{a}"]])
            assert d @ [sign, 0.0, 0.0] > np.cos(np.deg2rad(1.0)), f"{side} {a}->{b} not along {sign:+}x"
        for a, b in (("hip", "knee"), ("knee", "ankle")):
            d = unit(first[J[f"{side}_{b}"]] - first[J[f"{side}_{a}"]])
            assert d @ [0.0, -1.0, 0.0] > np.cos(np.deg2rad(1.0)), f"{side} leg not straight down"
    left = first[J["left_hip"]] - first[J["right_hip"]]
    front = unit(np.cross(left, [0.0, 1.0, 0.0]))
    assert front @ [0.0, 0.0, 1.0] > np.cos(np.deg2rad(2.0))
    assert abs(first[0, 0]) < 1e-9 and abs(first[0, 2]) < 1e-9
    assert first[[J["left_ankle"], J["right_ankle"]], 1].min() == pytest.approx(0.08, abs=1e-9)
    # held still for the hold time, then moving
    n_hold = round(0.5 * fps)
    assert np.abs(joints[:n_hold] - first).max() < 1e-12
    assert np.abs(joints[-1] - first).max() > 0.05


def test_lead_in_keeps_bone_lengths_and_moves_smoothly(lead_in):
    from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh

    joints = lead_in["joints"]
    lengths = sk.measure_bone_lengths(joints)
    raw = sk.measure_bone_lengths(motion16_from_bvh(BVH)["joints"])
    raw_range = raw.max(axis=0) - raw.min(axis=0)
    ours_range = lengths.max(axis=0) - lengths.min(axis=0)
    # bones that are rigid in the source stay within 0.1 mm; the spine bone (hips->chest spans CMU's
    # bending lower back) varies no more than it does in the raw clip
    assert (ours_range <= raw_range + 1e-4).all(), ours_range * 1000
    assert (ours_range[raw_range < 1e-6] < 1e-4).all()
    # no jumps: through hold and blend (first 1 s) the largest frame-to-frame joint step stays small
    # (the arms swinging down from the T-pose peak at about 2 m/s)
    step = np.linalg.norm(np.diff(joints[:121], axis=0), axis=-1).max()
    assert 0.005 < step < 0.025  # metres per 1/120 s


def test_synthetic_pipeline_file_loads():
    from tbha_graph.core.runner import load_graph

    graph = load_graph(ROOT / "pipelines" / "synthetic.yaml")
    assert set(graph.outputs) == {"sample.mp4", "ground_truth.npz"}


def test_lead_in_turn_turns_heading_and_path_keeping_bones():
    """turn_degrees turns the clip's heading and its walking direction together (a walk that turns round)."""
    from tbha_graph.mocap.synth.tpose_lead_in import LeadInParams, _facing_angle, lead_in_motion

    if not BVH.is_file():
        pytest.skip(f"{BVH} missing")
    base = dict(path=str(BVH), hold_seconds=0.2, blend_seconds=0.2, duration=3.0)
    straight, _ = lead_in_motion(LeadInParams(**base))
    turned, _ = lead_in_motion(LeadInParams(**base, turn_degrees=180.0, turn_start=0.5, turn_seconds=2.0))
    h0 = np.degrees(np.unwrap([_facing_angle(f) for f in straight]))
    h1 = np.degrees(np.unwrap([_facing_angle(f) for f in turned]))
    assert abs((h1[-1] - h0[-1]) - 180.0) < 2.0
    np.testing.assert_allclose(turned[:30], straight[:30], atol=1e-9)  # before the turn: unchanged
    lengths = sk.measure_bone_lengths(turned) - sk.measure_bone_lengths(straight)
    assert np.abs(lengths).max() < 1e-6
    # the path turns too: the late displacement points another way than without the turn
    d0, d1 = straight[-1, 0] - straight[-60, 0], turned[-1, 0] - turned[-60, 0]
    assert np.linalg.norm(d0[[0, 2]]) > 0.05
    cos = (d0[[0, 2]] @ d1[[0, 2]]) / np.linalg.norm(d0[[0, 2]]) / np.linalg.norm(d1[[0, 2]])
    assert cos < -0.8
