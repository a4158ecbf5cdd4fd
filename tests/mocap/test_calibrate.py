"""Calibration nodes: coplanar Tsai, PnP, camera files, checkerboard intrinsics."""
from __future__ import annotations

import json

import numpy as np
import pytest
from pydantic import ValidationError

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.calibrate.checkerboard import checkerboard
from tbha_graph.mocap.calibrate.known import known
from tbha_graph.mocap.calibrate.pnp import pnp
from tbha_graph.mocap.calibrate.tsai_coplanar import rotation_angle_deg, tsai_coplanar
from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.io.video import video as VIDEO_NODE
from tbha_graph.mocap.body import body_lengths, tpose_on_floor
from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES

W, H = 640, 480
REST = tpose_on_floor(body_lengths(None))  # the calibration world: T-pose on z = 0, floor y = 0


def tracks_of(cam: Camera, joints: np.ndarray, n: int = 5, noise: float = 0.0, seed: int = 0) -> dict:
    pts = np.repeat(cam.project(joints)[None], n, axis=0)
    pts = pts + np.random.default_rng(seed).normal(0.0, noise, pts.shape)
    return {"points": pts, "tracked": np.ones((n, 16), bool), "fps": np.array(30.0), "width": np.array(W), "height": np.array(H)}


# eye, target, focal: actor left of the image centre, right of it, camera high, camera low looking down at the feet
CAMERAS = {
    "actor_left_of_centre": ((0.9, 1.4, 4.5), (0.6, 1.0, 0.0), 800.0),
    "actor_right_of_centre": ((-0.6, 1.3, 4.8), (-0.5, 1.1, 0.0), 700.0),
    "high_looking_down": ((-1.0, 2.4, 4.0), (0.2, 0.9, 0.0), 850.0),
    "floor_above_axis": ((0.6, 0.25, 3.5), (0.2, -0.3, 0.0), 380.0),
}


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_tsai_recovers_camera_from_exact_torso(name):
    eye, target, f = CAMERAS[name]
    cam = Camera.look_at(eye, target, focal_px=f, width=W, height=H)
    out = run_node(tsai_coplanar, {}, tracks=tracks_of(cam, REST))
    got = out["camera"].camera()
    assert got.K[0, 0] == pytest.approx(f, rel=0.01)
    assert rotation_angle_deg(got.R, cam.R) < 1e-3
    assert np.allclose(got.t, cam.t, atol=1e-5)
    # camera frame convention: the chest is in front of the camera and inside the image
    chest = REST[JOINT_INDEX["chest"]]
    assert got.to_camera(chest)[2] > 0 and got.in_image(got.project(chest))
    assert out["report"]["reprojection_rms_px"] < 1e-6
    assert out["report"]["camera_in_front_of_actor"]


def test_tsai_ty_sign_both_ways():
    signs = set()
    for eye, target, f in CAMERAS.values():
        cam = Camera.look_at(eye, target, focal_px=f, width=W, height=H)
        signs.add(run_node(tsai_coplanar, {}, tracks=tracks_of(cam, REST))["report"]["ty_sign"])
        assert np.sign(cam.t[1]) in signs
    assert signs == {1, -1}


def test_tsai_spine_through_image_centre_is_a_clear_error_and_more_joints_fix_it():
    cam = Camera.look_at((0.0, 1.4, 4.5), (0.0, 1.0, 0.0), focal_px=800.0, width=W, height=H)
    with pytest.raises(NodeError, match="singular") as e:
        run_node(tsai_coplanar, {}, tracks=tracks_of(cam, REST))
    assert "joints" in e.value.hint
    out = run_node(tsai_coplanar, {"joints": list(JOINT_NAMES)}, tracks=tracks_of(cam, REST))
    assert out["camera"].K[0][0] == pytest.approx(800.0, rel=0.01)


def test_tsai_reports_sensitivity_and_known_focal_helps():
    eye, target, f = CAMERAS["actor_left_of_centre"]
    cam = Camera.look_at(eye, target, focal_px=f, width=W, height=H)
    free = run_node(tsai_coplanar, {}, tracks=tracks_of(cam, REST))["report"]
    many = run_node(tsai_coplanar, {"joints": list(JOINT_NAMES)}, tracks=tracks_of(cam, REST))["report"]
    fixed = run_node(tsai_coplanar, {"focal_px": f}, tracks=tracks_of(cam, REST))["report"]
    assert many["rotation_sd_deg_per_px"] < free["rotation_sd_deg_per_px"]
    assert fixed["focal_sd_px_per_px"] == 0.0 and fixed["focal_px"] == f
    assert "warning" in free  # a near-frontal torso is a weak calibration target: said, not hidden


def test_tsai_refine_reduces_reprojection_error_on_noisy_points():
    eye, target, f = CAMERAS["high_looking_down"]
    cam = Camera.look_at(eye, target, focal_px=f, width=W, height=H)
    tr = tracks_of(cam, REST, n=1, noise=0.7, seed=3)
    joints = list(JOINT_NAMES)
    raw = run_node(tsai_coplanar, {"joints": joints}, tracks=tr)["report"]
    ref = run_node(tsai_coplanar, {"joints": joints, "refine": True}, tracks=tr)["report"]
    assert ref["reprojection_rms_px"] <= raw["reprojection_rms_px"] + 1e-9


def test_tsai_bad_joint_name_is_refused_with_suggestion():
    with pytest.raises(ValidationError, match="did you mean 'chest'"):
        tsai_coplanar.params.model_validate({"joints": ["neck", "chst", "hips", "left_shoulder", "right_shoulder"]})


def test_tsai_needs_tracked_torso():
    cam = Camera.look_at(*CAMERAS["actor_left_of_centre"][:2], focal_px=800.0, width=W, height=H)
    tr = tracks_of(cam, REST)
    tr["tracked"][:, JOINT_INDEX["neck"]] = False
    with pytest.raises(NodeError, match="T-pose"):
        run_node(tsai_coplanar, {}, tracks=tr)
    del tr["width"]
    with pytest.raises(NodeError, match="width"):
        run_node(tsai_coplanar, {}, tracks=tr)


@pytest.mark.parametrize("name", ["actor_left_of_centre", "high_looking_down"])
def test_pnp_recovers_pose_and_agrees_with_tsai(name):
    eye, target, f = CAMERAS[name]
    cam = Camera.look_at(eye, target, focal_px=f, width=W, height=H)
    tr = tracks_of(cam, REST)
    got = run_node(pnp, {"focal_px": f}, tracks=tr)["camera"].camera()
    assert rotation_angle_deg(got.R, cam.R) < 1e-4 and np.allclose(got.t, cam.t, atol=1e-5)
    tsai = run_node(tsai_coplanar, {}, tracks=tr)["camera"].camera()
    assert rotation_angle_deg(got.R, tsai.R) < 1e-3 and np.allclose(got.t, tsai.t, atol=1e-4)
    # with 1 px noise on all 16 T-pose joints, PnP stays close (known focal)
    noisy = run_node(pnp, {"focal_px": f, "joints": list(JOINT_NAMES)}, tracks=tracks_of(cam, REST, noise=1.0, n=1))
    c = noisy["camera"].camera()
    assert rotation_angle_deg(c.R, cam.R) < 2.0 and np.linalg.norm(c.center - cam.center) < 0.15


def test_pnp_params_need_exactly_one_intrinsics():
    with pytest.raises(ValidationError, match="exactly one"):
        pnp.params.model_validate({})
    with pytest.raises(ValidationError, match="exactly one"):
        pnp.params.model_validate({"focal_px": 800, "K": [[800, 0, 320], [0, 800, 240], [0, 0, 1]]})


def _camera_dict() -> dict:
    cam = Camera.look_at((0.5, 1.5, 4.0), (0.0, 1.0, 0.0), focal_px=750.0, width=W, height=H)
    return cam.to_dict()


def test_known_reads_renderer_npz(tmp_path):
    d = _camera_dict()
    path = tmp_path / "ground_truth.npz"
    np.savez(path, K=np.array(d["K"]), R=np.array(d["R"]), t=np.array(d["t"]), width=np.array(W), height=np.array(H),
             joints=np.zeros((3, 16, 3)))
    out = run_node(known, {"path": path})
    assert np.allclose(out["camera"].K, d["K"]) and np.allclose(out["camera"].t, d["t"])
    assert (out["camera"].width, out["camera"].height) == (W, H)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_known_reads_yaml_and_json(tmp_path, suffix):
    import yaml

    d = _camera_dict()
    d["dist"] = [0.01, -0.002, 0.0, 0.0]
    path = tmp_path / f"cam{suffix}"
    path.write_text(yaml.safe_dump({"camera": d}) if suffix == ".yaml" else json.dumps(d))
    cam = run_node(known, {"path": path})["camera"]
    assert np.allclose(cam.R, d["R"]) and cam.dist == [0.01, -0.002, 0.0, 0.0, 0.0]


def test_known_errors_name_file_and_keys(tmp_path):
    d = _camera_dict()
    del d["t"], d["height"]
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(d))
    with pytest.raises(NodeError, match=r"cam\.json: missing key\(s\) t, height"):
        run_node(known, {"path": path})
    d = _camera_dict()
    d["R"] = (2.0 * np.array(d["R"])).tolist()
    path.write_text(json.dumps(d))
    with pytest.raises(NodeError, match="not a rotation"):
        run_node(known, {"path": path})
    path.write_text("{not json")
    with pytest.raises(NodeError, match=r"cam\.json:1:2: invalid JSON"):
        run_node(known, {"path": path})


def _board_texture(cols, rows, square):
    """A checkerboard texture (grey uint8) with ``cols`` x ``rows`` inner corners, ``S`` (3, 3) taking board metres
    to its pixels, and the board's centre (3,) metres."""
    px = 24  # texture pixels per square
    tex = np.full(((rows + 3) * px, (cols + 3) * px), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                tex[(r + 1) * px:(r + 2) * px, (c + 1) * px:(c + 2) * px] = 0
    # board metres -> texture pixels: inner corner (0, 0) sits at texture ((2 px) - 0.5, (2 px) - 0.5)
    S = np.array([[px / square, 0, 2 * px - 0.5], [0, px / square, 2 * px - 0.5], [0, 0, 1]])
    return tex, S, np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0.0])


def _render_board_views(folder, K, cols, rows, square, n_views, seed=0, lens=None):
    """Synthetic checkerboard photos: a board texture warped by the homography K [r1 r2 t]; ``lens`` (optional, a
    :class:`DistortingLens`) bends each photo as that lens would."""
    import cv2
    from scipy.spatial.transform import Rotation

    tex, S, centre = _board_texture(cols, rows, square)
    rng = np.random.default_rng(seed)
    for i in range(n_views):
        R = Rotation.from_euler("xyz", rng.uniform(-35, 35, 3), degrees=True).as_matrix()
        t = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.05, 0.05), rng.uniform(0.6, 0.85)]) - R @ centre
        Hm = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ np.linalg.inv(S)
        img = cv2.warpPerspective(tex, Hm, (W, H), flags=cv2.INTER_LINEAR, borderValue=128)
        cv2.imwrite(str(folder / f"view{i:02d}.png"), img if lens is None else lens.bend(img))


def test_checkerboard_focal_within_one_percent(tmp_path):
    K = np.array([[720.0, 0, 319.5], [0, 720.0, 239.5], [0, 0, 1]])
    _render_board_views(tmp_path, K, 9, 6, 0.03, 10)
    (tmp_path / "notes.txt").write_text("not an image")
    out = run_node(checkerboard, {"path": tmp_path, "columns": 9, "rows": 6, "square_size": 0.03})
    rep = out["report"]
    print(f"checkerboard: fx={rep['fx_px']:.2f} fy={rep['fy_px']:.2f} (true 720) rms={rep['rms_reprojection_px']:.3f} px")
    assert rep["views_used"] == 10
    assert rep["fx_px"] == pytest.approx(720.0, rel=0.01) and rep["fy_px"] == pytest.approx(720.0, rel=0.01)
    assert rep["rms_reprojection_px"] < 0.5
    # extrinsics of the first view: the board's first corner lies in front of the camera
    assert out["camera"].camera().to_camera(np.zeros(3))[2] > 0.3


def test_checkerboard_pipeline_gives_the_focal_length_for_the_capture(tmp_path, monkeypatch, capsys):
    """``pipelines/checkerboard.yaml`` (what docs/capture.md tells a user to run) writes lens.json with fx_px."""
    import json
    from pathlib import Path

    from tbha_graph.cli.run import main

    K = np.array([[720.0, 0, 319.5], [0, 720.0, 239.5], [0, 0, 1]])
    _render_board_views(tmp_path, K, 9, 6, 0.03, 8)
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "cache"))
    pipe = Path(__file__).resolve().parents[2] / "pipelines" / "checkerboard.yaml"
    assert main([str(pipe), "--var", f"clip={tmp_path}", "--set", "calibrate.square_size=0.03",
                 "--out", str(tmp_path / "lens"), "-q"]) == 0
    rep = json.loads((tmp_path / "lens" / "lens.json").read_text())
    assert rep["fx_px"] == pytest.approx(720.0, rel=0.01) and rep["views_used"] == 8
    assert (rep["width"], rep["height"]) == (W, H)  # io.video's lens checks the video's size against it
    import cv2

    picture = cv2.imread(str(tmp_path / "lens" / "lens.png"))  # the board as filmed | with the lens taken out
    assert picture is not None and picture.shape == (H, 2 * W, 3)
    assert rep["bend_px_at_corners"] < 0.5  # a pinhole lens (measured 0.2 px)


def test_checkerboard_wrong_board_size_is_explained(tmp_path):
    K = np.array([[720.0, 0, 319.5], [0, 720.0, 239.5], [0, 0, 1]])
    _render_board_views(tmp_path, K, 9, 6, 0.03, 3)
    with pytest.raises(NodeError, match="found in 0 of 3") as e:
        run_node(checkerboard, {"path": tmp_path, "columns": 7, "rows": 5, "square_size": 0.03})
    assert "inner corners" in e.value.hint


class DistortingLens:
    """A wide-angle lens (OpenCV's model: ``K``, ``dist`` k1 k2 p1 p2 k3) bending ideal pinhole images of size
    ``W`` x ``H``: each output pixel takes the pinhole image's pixel its ray comes from (remap tables made once)."""

    def __init__(self, K: np.ndarray, dist: np.ndarray):
        import cv2

        self.K, self.dist = K, dist
        u, v = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
        src = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), K, dist, P=K).reshape(H, W, 2)
        self.map_x, self.map_y = np.ascontiguousarray(src[..., 0]), np.ascontiguousarray(src[..., 1])

    def bend(self, img: np.ndarray) -> np.ndarray:
        import cv2

        return cv2.remap(img, self.map_x, self.map_y, cv2.INTER_LINEAR, borderValue=128)


#: An action camera's barrel distortion at the sample's focal length: 37 px at the image's corners
WIDE = DistortingLens(np.array([[700.0, 0, 319.5], [0, 700.0, 239.5], [0, 0, 1]]), np.array([-0.25, 0.08, 0.0, 0.0, 0.0]))


@pytest.fixture(scope="module")
def wide_take(tmp_path_factory):
    """The sample's first 40 frames as the wide lens films them (MJPG), and the lens.json that
    ``calibrate.checkerboard`` writes for that lens from 12 bent board photos."""
    from tbha_graph.core.atomic import atomic_write_text

    folder = tmp_path_factory.mktemp("wide")
    (folder / "board").mkdir()
    _render_board_views(folder / "board", WIDE.K, 9, 6, 0.03, 12, lens=WIDE)
    rep = run_node(checkerboard, {"path": folder / "board", "columns": 9, "rows": 6, "square_size": 0.03})["report"]
    lens = folder / "lens.json"
    atomic_write_text(lens, json.dumps(rep))
    originals = _bent_sample(folder / "wide.avi", WIDE, 40)
    return folder / "wide.avi", lens, rep, originals


def _bent_sample(path, lens, n: int) -> np.ndarray:
    """The sample's first ``n`` frames bent by ``lens`` (its ``bend``) written to ``path`` as MJPG; returns the
    unbent frames ``(n, H, W, 3)``."""
    import cv2

    from pathlib import Path

    cap = cv2.VideoCapture(str(Path(__file__).resolve().parents[2] / "data" / "sample" / "sample.mp4"))
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (W, H))
    originals = []
    for _ in range(n):
        ok, frame = cap.read()
        originals.append(frame)
        out.write(lens.bend(frame))
    out.release()
    cap.release()
    return np.array(originals)


def test_a_lens_file_takes_the_wide_lens_out_of_every_frame(wide_take):
    """A wide-angle take read with its lens.json (io.video's ``lens``) gives the frames the pinhole camera would have
    filmed: every later stage assumes one. Measured: the calibrated lens (k1 -0.260, k2 0.145 against -0.25, 0.08:
    the two trade off) undistorts within 1.03 px of the true one; edges away from the image's centre lie 0.47 px
    (median, dense optical flow) from where the pinhole camera puts them, 5.3 px in the bent frames as read."""
    from tbha_graph.mocap.calibrate.vanishing_points import LENS_FILE_SD_PCT

    path, lens, rep, originals = wide_take
    import cv2

    grid = np.stack(np.meshgrid(np.linspace(40, W - 41, 12), np.linspace(40, H - 41, 9)), -1).reshape(-1, 1, 2)
    K = np.array([[rep["fx_px"], 0, rep["cx_px"]], [0, rep["fy_px"], rep["cy_px"]], [0, 0, 1]])
    model_err = np.linalg.norm(cv2.undistortPoints(grid, K, np.array(rep["dist"]), P=WIDE.K)
                               - cv2.undistortPoints(grid, WIDE.K, WIDE.dist, P=WIDE.K), axis=-1).max()
    from tbha_graph.mocap.calibrate.checkerboard import bend_at_corners

    true_bend = bend_at_corners(WIDE.K, WIDE.dist, W, H)
    print(f"calibrated lens: k1 {rep['dist'][0]:.3f} k2 {rep['dist'][1]:.3f}, undistortion off by {model_err:.2f} px at most; "
          f"the corners bent {rep['bend_px_at_corners']:.2f} px (truth {true_bend:.2f})")
    assert rep["bend_px_at_corners"] == pytest.approx(true_bend, abs=4.5)  # measured 34.1 against 37.1 (the extreme corners, beyond the boards)
    assert model_err < 1.5  # the bent board photos give the lens back (measured 1.03 px, at the corners)
    straight = run_node(VIDEO_NODE, {"path": path, "lens": lens})["video"]
    bent = run_node(VIDEO_NODE, {"path": path})["video"]
    assert straight.lens is not None and straight.lens.focal_px == pytest.approx(700.0, rel=0.005) and bent.lens is None
    shift = {name: _edge_shift(clip, originals[::10], range(0, 40, 10)) for name, clip in (("straight", straight), ("bent", bent))}
    print(f"lens file: edges away from the centre {shift['straight']:.2f} px from the pinhole frames' "
          f"(without it {shift['bent']:.2f} px)")
    assert shift["straight"] < 0.7 and shift["bent"] > 3.5, shift  # measured 0.47 and 5.3 px
    assert LENS_FILE_SD_PCT <= 1.0


def test_a_lens_file_gives_the_solver_its_focal_length(wide_take):
    """The bent take's room lines no longer meet where a pinhole camera's would: ``calibrate.vanishing_points`` finds
    no focal length from them (measured: 1471 px ± 15 %, refused), so the solver would guess it from the motion alone.
    With the lens file the frames are straight again and the file's focal length is the solver's start and prior."""
    from tbha_graph.mocap.calibrate.vanishing_points import vanishing_points

    path, lens, rep, _ = wide_take
    bent = run_node(vanishing_points, {}, video=run_node(VIDEO_NODE, {"path": path})["video"])["lens"]
    straight = run_node(vanishing_points, {}, video=run_node(VIDEO_NODE, {"path": path, "lens": lens})["video"])["lens"]
    print(f"room lines: {bent.source}; with the lens file: {straight.source}")
    assert bent.focal_px is None or abs(bent.focal_px / 700.0 - 1.0) > 0.05, bent
    assert straight.source.startswith("lens file lens.json")
    assert straight.focal_px == pytest.approx(0.5 * (rep["fx_px"] + rep["fy_px"]), abs=0.01)
    assert straight.up_cam is not None  # the room's lines, straight again, agree with it: the floor's tilt too


def test_a_lens_file_of_another_zoom_is_questioned_by_the_rooms_lines(wide_take, tmp_path):
    """A lens.json whose focal length is 20 % short (calibrated at another zoom): the room's lines in the frames it
    straightens give 787 px ± 3.4 % against its 560 (measured), and the run warns; the right file (lines 701 px
    against 700) does not."""
    from tbha_graph.core.node import Context
    from tbha_graph.mocap.calibrate.vanishing_points import vanishing_points

    path, lens, rep, _ = wide_take
    short = tmp_path / "zoomed_lens.json"
    short.write_text(json.dumps({**rep, "fx_px": 0.8 * rep["fx_px"], "fy_px": 0.8 * rep["fy_px"]}))
    warned = {}
    for name, file in (("right", lens), ("short", short)):
        ctx = Context("lens", vanishing_points.params.model_validate({}))
        out = vanishing_points.fn(ctx, run_node(VIDEO_NODE, {"path": path, "lens": file})["video"])
        print(f"{name} lens file: the room's lines {out['report']['focal_px']} px ± {out['report']['focal_sd_pct']} %")
        warned[name] = ctx.warnings
    assert warned["right"] == []
    (warning,) = warned["short"]
    assert "lens file zoomed_lens.json 56" in warning and "another camera or zoom" in warning


def test_a_lens_file_of_another_camera_or_no_lens_file_is_named(wide_take, tmp_path):
    path, lens, rep, _ = wide_take
    half = run_node(VIDEO_NODE, {"path": path, "lens": lens, "scale": 0.5})["video"]  # downscaled frames: the lens too
    assert half.lens.focal_px == pytest.approx(0.25 * (rep["fx_px"] + rep["fy_px"]))
    assert half.lens.K[0][2] == pytest.approx(0.5 * (rep["cx_px"] + 0.5) - 0.5)  # pixel centres kept
    other = tmp_path / "phone_lens.json"
    other.write_text(json.dumps({**rep, "width": 1920, "height": 1080}))
    with pytest.raises(NodeError, match=r"phone_lens\.json: calibrated on 1920x1080 frames, the video's are 640x480"):
        run_node(VIDEO_NODE, {"path": path, "lens": other})
    other.write_text(json.dumps({"fx_px": 700.0}))
    with pytest.raises(NodeError, match=r"phone_lens\.json: no fy_px, cx_px, cy_px, dist, width, height"):
        run_node(VIDEO_NODE, {"path": path, "lens": other})
    other.write_text("{not json")
    with pytest.raises(NodeError, match=r"invalid JSON \(lens file\)") as e:
        run_node(VIDEO_NODE, {"path": path, "lens": other})
    assert "phone_lens.json:1:2" in str(e.value)


class FisheyeLens:
    """A fisheye lens (OpenCV's fisheye model: ``K``, ``dist`` k1..k4 of the angle off the axis) on ``W`` x ``H``
    frames: :meth:`rays` gives each filmed pixel's ray, :meth:`bend` bends an ideal pinhole image of focal length
    ``K[0, 0]`` (remap tables made once)."""

    def __init__(self, K: np.ndarray, dist: np.ndarray):
        import cv2

        self.K, self.dist = K, dist
        u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
        self.normalised = cv2.fisheye.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), K, dist).reshape(H, W, 2)
        src = (self.normalised * K[0, 0] + K[:2, 2]).astype(np.float32)
        self.map_x, self.map_y = np.ascontiguousarray(src[..., 0]), np.ascontiguousarray(src[..., 1])

    def bend(self, img: np.ndarray) -> np.ndarray:
        import cv2

        return cv2.remap(img, self.map_x, self.map_y, cv2.INTER_LINEAR, borderValue=128)

    def lens_json(self) -> dict:
        """The lens.json ``calibrate.checkerboard`` would write for this lens, exactly."""
        return {"model": "fisheye", "fx_px": self.K[0, 0], "fy_px": self.K[1, 1], "cx_px": self.K[0, 2],
                "cy_px": self.K[1, 2], "dist": self.dist.tolist(), "width": W, "height": H}


def _fisheye_board_views(folder, lens: FisheyeLens, cols, rows, square, n_views, seed=0):
    """Board photos filmed through ``lens`` directly (each filmed pixel's ray meets the board plane; no pinhole image
    in between, so boards reach the frame's corners), spread over the whole field of view."""
    import cv2
    from scipy.spatial.transform import Rotation

    tex, S, centre = _board_texture(cols, rows, square)
    rays = np.concatenate([lens.normalised, np.ones((H, W, 1))], -1)
    rng = np.random.default_rng(seed)
    for i in range(n_views):
        R = Rotation.from_euler("xyz", rng.uniform(-35, 35, 3), degrees=True).as_matrix()
        z = rng.uniform(0.45, 0.7)
        t = np.array([rng.uniform(-0.45, 0.45) * z, rng.uniform(-0.3, 0.3) * z, z]) - R @ centre
        to_tex = S @ np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], t]))  # normalised image -> texture pixels
        q = rays @ to_tex.T
        q = np.where(q[..., 2:] > 0, q[..., :2] / q[..., 2:], -1.0).astype(np.float32)
        img = cv2.remap(tex, np.ascontiguousarray(q[..., 0]), np.ascontiguousarray(q[..., 1]), cv2.INTER_LINEAR,
                        borderValue=128)
        cv2.imwrite(str(folder / f"view{i:02d}.png"), img)


#: an action camera's widest mode: 420 px focal length at 640x480, 70 degrees off the axis at the frame's corners
FISHEYE = FisheyeLens(np.array([[420.0, 0, 319.5], [0, 420.0, 239.5], [0, 0, 1]]), np.array([0.02, -0.01, 0.0, 0.0]))


def test_a_fisheye_lens_is_calibrated_with_the_fisheye_model(tmp_path):
    """``distortion: fisheye`` calibrates an action camera's widest mode, which the pinhole model's k1 k2 cannot
    follow at the frame's rim. Measured (12 board photos through the lens, the boards reaching 65 % of the way to the
    corners): both fits match the boards to 0.08 px, but the fisheye fit undistorts within 3.1 px of the true lens
    over the whole frame (1.1 px at its middle: the principal point, as 12 views find it) and k1 k2's is 41 px off at
    the rim; the straightened frames keep 73.7 % of the filmed one (truth 73.6), the corners bent 176 px (177.5)."""
    from tbha_graph.core.node import Context
    from tbha_graph.mocap.calibrate.checkerboard import bend_at_corners
    from tbha_graph.mocap.io.lens_file import ideal_points, view_kept

    _fisheye_board_views(tmp_path, FISHEYE, 9, 6, 0.03, 12)
    ctx = Context("calibrate", checkerboard.params.model_validate(
        {"path": tmp_path, "columns": 9, "rows": 6, "square_size": 0.03, "distortion": "fisheye"}))
    fish = checkerboard.fn(ctx)
    plain = run_node(checkerboard, {"path": tmp_path, "columns": 9, "rows": 6, "square_size": 0.03})["report"]
    rep = fish["report"]
    grid = np.stack(np.meshgrid(np.linspace(20, W - 21, 16), np.linspace(20, H - 21, 12)), -1).reshape(-1, 2)
    truth = ideal_points(grid, FISHEYE.K, FISHEYE.dist, "fisheye", FISHEYE.K)

    def off(r):  # how far the calibrated lens straightens the grid from where the true lens does, px (the worst)
        K = np.array([[r["fx_px"], 0, r["cx_px"]], [0, r["fy_px"], r["cy_px"]], [0, 0, 1]])
        return np.linalg.norm(ideal_points(grid, K, np.array(r["dist"]), r["model"], FISHEYE.K) - truth, axis=-1).max()

    true_kept = 100 * view_kept(FISHEYE.K, FISHEYE.dist, "fisheye", W, H, 420.0)
    true_bend = bend_at_corners(FISHEYE.K, FISHEYE.dist, W, H, "fisheye")
    print(f"fisheye fit: {rep['views_used']} views reaching {rep['board_reach_pct']} %, rms "
          f"{rep['rms_reprojection_px']:.3f} px, undistortion off by {off(rep):.2f} px at most; k1k2 fit rms "
          f"{plain['rms_reprojection_px']:.3f} px, off by {off(plain):.1f} px; bend {rep['bend_px_at_corners']} px "
          f"(truth {true_bend:.1f}), view kept {rep['view_kept_pct']} % (truth {true_kept:.1f})")
    assert rep["model"] == "fisheye" and len(rep["dist"]) == 4 and plain["model"] == "pinhole"
    assert rep["rms_reprojection_px"] < 0.15 and plain["rms_reprojection_px"] < 0.15  # both fit the boards (0.08)
    assert off(rep) < 4.5 and off(plain) > 25  # measured 3.06 and 40.6 px
    assert rep["view_kept_pct"] == pytest.approx(true_kept, abs=1.5) and rep["bend_px_at_corners"] == pytest.approx(true_bend, abs=5)
    (warning,) = ctx.warnings  # the boards kept to the middle: the rim is extrapolated, and the run says so
    assert "reached 65 % of the way" in warning and rep["warnings"] == [warning]
    cam = fish["camera"].camera()
    assert not np.any(cam.dist) and cam.K[0, 2] == pytest.approx((W - 1) / 2)  # the straightened frames' camera


#: a fisheye lens at the sample's focal length: its frames bent by it and straightened again by the lens file
FISHEYE_700 = FisheyeLens(np.array([[700.0, 0, 319.5], [0, 700.0, 239.5], [0, 0, 1]]), np.array([0.02, -0.01, 0.0, 0.0]))


def _edge_shift(clip, originals, frames) -> float:
    """Median distance, px (dense optical flow), between edges away from the image's centre in ``clip``'s ``frames``
    as read and in the pinhole ``originals`` (one per frame)."""
    import cv2

    from tbha_graph.mocap.io.video import iter_frames_at

    u, v = np.meshgrid(np.arange(W), np.arange(H))
    ring = np.hypot(u - 319.5, v - 239.5)
    ring = (ring > 150) & (np.minimum.reduce([u, v, W - 1 - u, H - 1 - v]) > 30)  # away from the centre, inside the frame
    moved = []
    for (_, frame), original in zip(iter_frames_at(clip, frames), originals):
        a, b = (cv2.cvtColor(x, cv2.COLOR_BGR2GRAY) for x in (original, frame))
        flow = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 3, 21, 3, 5, 1.1, 0)
        edges = np.hypot(cv2.Sobel(a, cv2.CV_32F, 1, 0), cv2.Sobel(a, cv2.CV_32F, 0, 1)) > 60
        moved.append(np.linalg.norm(flow, axis=-1)[ring & edges])
    return float(np.median(np.concatenate(moved)))


def test_a_fisheye_lens_file_straightens_the_take(tmp_path):
    """A take filmed through a fisheye lens, read with its lens.json (``"model": "fisheye"``), gives the pinhole
    camera's frames. Measured on 4 of the sample's frames bent by it (46 px at the corners): edges away from the
    centre 0.08 px from the pinhole frames, 6.5 px without the file; with ``lens_view: width`` 0.07 px from the
    pinhole frames zoomed out to the focal length that keeps the filmed width."""
    from tbha_graph.core.atomic import atomic_write_text

    originals = _bent_sample(tmp_path / "fish.avi", FISHEYE_700, 4)
    lens = tmp_path / "lens.json"
    atomic_write_text(lens, json.dumps(FISHEYE_700.lens_json()))
    straight = run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": lens})["video"]
    bent = run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi"})["video"]
    assert straight.lens.model == "fisheye" and straight.lens.focal_px == 700.0
    shift = {name: _edge_shift(clip, originals, range(4)) for name, clip in (("straight", straight), ("bent", bent))}
    print(f"fisheye lens file: edges away from the centre {shift['straight']:.2f} px from the pinhole frames' "
          f"(without it {shift['bent']:.2f} px)")
    assert shift["straight"] < 0.12 and shift["bent"] > 4.5, shift  # measured 0.08 and 6.5 px
    # lens_view=width: a shorter focal length keeps the filmed frame's sides in view: the pinhole frames, zoomed out
    whole = run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": lens, "lens_view": "width"})["video"]
    zoom = whole.lens.focal_px / 700.0
    import cv2

    zoomed = [cv2.warpAffine(f, cv2.getRotationMatrix2D((319.5, 239.5), 0.0, zoom), (W, H)) for f in originals]
    shift["whole"] = _edge_shift(whole, zoomed, range(4))
    print(f"lens_view=width: focal {whole.lens.focal_px:.1f} px, edges {shift['whole']:.2f} px from the zoomed-out pinhole frames'")
    # 653.5: the side's 319.5 px is 0.4564 rad through the lens (/700), 0.4547 rad off the axis (k1 k2), tan -> 0.4889
    assert whole.lens.focal_px == pytest.approx(653.5, abs=0.5) and shift["whole"] < 0.12  # measured 0.07 px
    # the run says how much of the filmed frame the straightened frames show (88 % at 700 px, 98 % at 653.5)
    from tbha_graph.core.node import Context

    class Lines:
        def __init__(self):
            self.lines = []

        def log(self, node_id, msg):
            self.lines.append(msg)

    said = {}
    for view in ("calibrated", "width"):
        lines = Lines()
        VIDEO_NODE.fn(Context("decode", VIDEO_NODE.params.model_validate(
            {"path": tmp_path / "fish.avi", "lens": lens, "lens_view": view}), reporter=lines), None)
        said[view] = lines.lines
    assert said["calibrated"] == ["lens file lens.json (fisheye): frames straightened to a 700 px pinhole camera, "
                                  "showing 88 % of the filmed frame (lens_view=width keeps its whole width)"]
    assert said["width"] == ["lens file lens.json (fisheye): frames straightened to a 653 px pinhole camera, "
                             "showing 98 % of the filmed frame"]
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({**FISHEYE_700.lens_json(), "dist": [0.02, -0.01, 0.0, 0.0, 0.1]}))
    with pytest.raises(NodeError, match=r"wrong\.json: a fisheye lens expects .* at most 4 finite distortion terms"):
        run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": wrong})
    wrong.write_text(json.dumps({**FISHEYE_700.lens_json(), "model": "omnidir"}))
    with pytest.raises(NodeError, match=r"wrong\.json: model 'omnidir' is not one of pinhole, fisheye"):
        run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": wrong})


def test_lens_files_of_gyroflow_and_ros_are_read(wide_take, tmp_path):
    """A Gyroflow lens profile (its database covers many action cameras' modes; OpenCV fisheye, scaled from another
    resolution of the same shape) and a ROS camera_info YAML straighten the take as our lens.json does."""
    from tbha_graph.core.atomic import atomic_write_text

    originals = _bent_sample(tmp_path / "fish.avi", FISHEYE_700, 4)
    K2 = FISHEYE_700.K * [[2, 1, 2], [1, 2, 2], [1, 1, 1]] + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]  # at 1280x960
    profile = {"name": "Test_Cam_Wide_4by3", "calib_dimension": {"w": 1280, "h": 960}, "use_opencv_fisheye": True,
               "fisheye_params": {"RMS_error": 0.3, "camera_matrix": K2.tolist(), "distortion_coeffs": FISHEYE_700.dist.tolist()}}
    gyro = tmp_path / "Test_Cam_Wide_4by3.json"
    atomic_write_text(gyro, json.dumps(profile))
    clip = run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": gyro})["video"]
    assert clip.lens.model == "fisheye" and clip.lens.focal_px == pytest.approx(700.0)
    assert clip.lens.K[0][2] == pytest.approx(319.5) and clip.lens.K[1][2] == pytest.approx(239.5)
    shift = _edge_shift(clip, originals, range(4))
    print(f"Gyroflow profile at 1280x960 on the 640x480 fisheye take: edges {shift:.2f} px from the pinhole frames'")
    assert shift < 0.12  # as our own lens.json of the lens (measured 0.08 px)
    wide16 = tmp_path / "wide_16by9.json"
    wide16.write_text(json.dumps({**profile, "calib_dimension": {"w": 1920, "h": 1080}}))
    with pytest.raises(NodeError, match=r"wide_16by9\.json: calibrated on 1920x1080 frames, the video's are 640x480"):
        run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": wide16})
    poly = tmp_path / "poly.json"
    poly.write_text(json.dumps({**profile, "distortion_model": "poly3"}))
    with pytest.raises(NodeError, match=r"poly\.json: a Gyroflow profile whose lens model \(poly3\) is not read"):
        run_node(VIDEO_NODE, {"path": tmp_path / "fish.avi", "lens": poly})

    path, lens, rep, _ = wide_take  # the barrel lens as a ROS camera_info file (plumb_bob)
    ros = tmp_path / "camera_info.yaml"
    K = [rep["fx_px"], 0, rep["cx_px"], 0, rep["fy_px"], rep["cy_px"], 0, 0, 1]
    ros.write_text(f"image_width: {W}\nimage_height: {H}\ncamera_name: test\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                   f"  data: {K}\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
                   f"  data: {rep['dist']}\n")
    from_ros = run_node(VIDEO_NODE, {"path": path, "lens": ros})["video"].lens
    ours = run_node(VIDEO_NODE, {"path": path, "lens": lens})["video"].lens
    assert from_ros.model_dump(exclude={"source"}) == ours.model_dump(exclude={"source"})
    ros.write_text(ros.read_text().replace("plumb_bob", "rational_polynomial"))
    with pytest.raises(NodeError, match=r"camera_info\.yaml: distortion_model 'rational_polynomial' is not read"):
        run_node(VIDEO_NODE, {"path": path, "lens": ros})
