"""The product: `pipelines/default.yaml` on the bundled sample writes a BVH whose forward kinematics
reproduces joints3d.npz, and reports its accuracy against the sample's ground truth."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tbha_graph.core.cache import Cache
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.mocap.evaluate.measures import align_clip
from tbha_graph.mocap.io.bvh import bvh_positions, read_bvh
from tbha_graph.mocap.skeleton import JOINT_NAMES

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("default") / "run"
    g = load_graph(ROOT / "pipelines" / "default.yaml")
    run_graph(g, out_dir=out, outputs=["motion.bvh", "joints3d.npz", "metrics.json"], cache=Cache(out.parent / "cache"))
    return out


def test_bvh_reproduces_joints3d_within_1mm(run_dir):
    bvh = read_bvh(run_dir / "motion.bvh")
    assert bvh.names == list(JOINT_NAMES)
    with np.load(run_dir / "joints3d.npz", allow_pickle=False) as z:
        joints, names, tracked = z["joints"], z["joint_names"], z["tracked"]
        assert {"K", "R", "t", "fps", "inferred"} <= set(z.files)
    assert list(names) == list(JOINT_NAMES) and tracked.shape == joints.shape[:2]
    err = np.linalg.norm(bvh_positions(bvh) - joints, axis=-1)
    assert err.max() < 1e-3  # metres


def test_metrics_against_ground_truth(run_dir):
    m = json.loads((run_dir / "metrics.json").read_text())
    assert m["frames"] == 210 and m["tracked_pct"] > 95
    assert m["tracking_2d_px_median"] < 1.5  # tracker vs the true patch centres
    assert m["tpose_prior_frames"] == 33  # the opening T-pose held: frames 0-32
    documented = (ROOT / "docs" / "metrics.md").read_text()  # every key the default run writes is explained
    assert [k for k in m if f"`{k}`" not in documented] == []
    # figures measured on this sample (see README), bounds about 1.5x: a regression past them is a real loss
    assert m["mpjpe_alignment"] == "rigid" and m["alignment_scale"] == 1  # headline: no scale hides the camera
    # measured 49.5 / 26.0 (round 21's lean search; 59.0 / 27.1 before): the tracks as they are are one draw of a chaotic
    # solve, the sample's three draws (bench/solver_sweep.py --repeats 3) 49.5-52.7, mean 50.9 (49.5-59.0 before)
    assert m["mpjpe_mm"] < 73 and m["pa_mpjpe_mm"] < 38
    # where the BVH puts the joints (joints3d.npz "joints"), scored the same way: measured 47.76 / 26.22 against the
    # solver's 47.74 / 26.90 with rotations' torso_fit (50.57 / 27.65 before it; 51.3 / 25.2 before feet_reach, 62.6 /
    # 26.6 before round 21): the rigid torso fitted by least squares costs the BVH 0.02 mm here, not 2.8
    z = np.load(run_dir / "joints3d.npz")
    assert m["export_mpjpe_mm"] < 75 and m["export_pa_mpjpe_mm"] < 37
    assert m["export_mpjpe_mm"] < m["mpjpe_mm"] + 0.5 and m["export_pa_mpjpe_mm"] < m["pa_mpjpe_mm"] + 0.5
    truth = np.load(ROOT / "data" / "sample" / "ground_truth.npz")["joints3d_world"]
    aligned, _ = align_clip(z["joints"], truth, "rigid")
    assert abs(np.linalg.norm(aligned - truth, axis=-1).mean() * 1000 - m["export_mpjpe_mm"]) < 0.01
    assert m["root_mpjpe_mm"] < 64 and m["joint_angle_err_deg"] < 9.5  # measured 46.8 mm / 6.0 deg (47.6 / 6.2 before)
    assert m["floor_penetration_mm"] < 3.7 and m["foot_skate_mm"] < 4.0  # measured 2.1 / 2.7 (2.5 / 2.8 before round 21)
    # the BVH's feet where the solver planted them (rotations' feet_reach): measured 2.0 / 2.6, as the solver's; 18.4 / 3.2
    # without it (the rigid pelvis moved each leg by its miss)
    assert m["export_floor_penetration_mm"] < 3.1 and m["export_foot_skate_mm"] < 4.0
    # the focal length from the room's floor tiles (calibrate.vanishing_points: 698.5 px ± 0.7 %; 702.1 before the
    # sub-pixel refit), refined by the take: measured -0.20 % (-0.16 before round 21, +0.39 % before round 20; the
    # take alone: +2.6 % from the luckiest of five starting grids, median +31 %)
    assert abs(m["focal_err_pct"]) < 0.6 and m["focal_source"].startswith("room lines")
    assert not any("focal length is" in w for w in m["warnings"])  # neither ambiguous nor uncertain now
    # no node warns on the bundled sample (its unknown background does not matter: its torso is seen on every
    # frame, segment.silhouette), so its verdict is ok; metrics.json lists warnings even when there are none
    assert m["warnings"] == [] and m["verdict"] == "ok", (m["warnings"], m["verdict_reasons"])
    # the floor's tilt from the room too: the camera's height within 1.5 cm of the truth (measured -0.52 cm; -0.97
    # before round 20's room lines)
    assert m["floor_source"] == "room lines" and abs(m["camera_height_err_m"]) < 0.015
    assert {"focal_px", "focal_sd_pct", "camera_height_m", "camera_distance_m", "camera_tilt_deg"} <= set(m)
    assert "focal_fits_px_min" not in m and m["focal_sd_pct"] < 0.35  # one start (the room's); measured 0.22 %
    # the solver's fit of the patches as it models them reaches metrics.json beside the joint-centre reprojection
    # (patches sit off their joints): measured 0.40 px median, 1.38 p95, against 3.2 px
    assert m["fit_px_median"] < 0.57 and m["fit_px_p95"] < 2.05 and m["reprojection_px_median"] > 2.0
    # the room's lines the focal length came from, drawn: both families (red, blue) on the sample's floor
    import cv2

    lines = cv2.imread(str(run_dir / "room_lines.png"))
    assert lines.shape == (480, 640, 3)
    b, g, r = (lines[..., k].astype(int) for k in range(3))
    assert ((r > 200) & (g < 80) & (b < 80)).sum() > 2000 and ((b > 200) & (r < 80)).sum() > 1000
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["nodes"]["reconstruct"]["type"] == "reconstruct.solve_take"


def test_summary_says_where_the_focal_length_came_from(run_dir, monkeypatch, capsys):
    """The run summary's focal length names its source: the room's lines on the sample (cached: no re-run)."""
    import re

    from tbha_graph.cli.run import main

    monkeypatch.setenv("TBHA_CACHE_DIR", str(run_dir.parent / "cache"))
    assert main([str(ROOT / "pipelines" / "default.yaml"), "--out", str(run_dir.parent / "again"), "-q"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"focal_px (69\d|70\d)(\.\d+)? \(room lines\)", out), out
