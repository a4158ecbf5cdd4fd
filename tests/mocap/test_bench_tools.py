"""The benches' own helpers: ``bench/render_robustness.py --keep DIR --set ...`` puts runs with different settings in
different folders, so a second setting never replaces the first's run (it did until round 21: both went to
``run_set/``); ``bench/solver_sweep.py --consistent-patches`` moves the tracks onto the solver's patch model."""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
import numpy as np  # noqa: E402
from render_robustness import set_suffix  # noqa: E402
from solver_sweep import consistent_points  # noqa: E402

from tbha_graph.mocap.reconstruct.take_model import DEFAULT_POINT_OFFSETS, point_positions  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, PATCHED_JOINTS  # noqa: E402


def test_each_setting_has_its_own_run_folder():
    assert set_suffix([]) == ""
    a = set_suffix(["reconstruct.sigma_px=1.5"])
    b = set_suffix(["reconstruct.sigma_px=2.0"])
    assert a.startswith("_set_") and len(a) == len("_set_") + 8 and a != b
    both = ["reconstruct.sigma_px=1.5", "track.gate_px=9"]
    assert set_suffix(both) == set_suffix(both[::-1]) != a  # order-free, and not the single setting's


def test_consistent_patches_put_a_perfect_tracker_on_the_model():
    """The sample's true patch centres (a perfect tracker) made consistent at the ankles land where the solver's patch
    model puts the ankles' patches on the true joints (to 1e-9 px); the other joints keep the renderer's centres. The
    renderer's ankle patch is 0.84 px from the model's at the median, 4.2 px at worst (it slides up the shin)."""
    with np.load(ROOT / "data" / "sample" / "ground_truth.npz") as z:
        truth = {k: z[k] for k in ("joints3d_cam", "K", "patch2d", "joints2d")}
    points = truth["joints2d"].copy()
    idx = [JOINT_INDEX[n] for n in PATCHED_JOINTS]
    points[:, idx] = truth["patch2d"]
    ankles = ("left_ankle", "right_ankle")
    out = consistent_points(points, truth, ankles)
    model = point_positions(truth["joints3d_cam"], DEFAULT_POINT_OFFSETS) @ truth["K"].T
    model = model[..., :2] / model[..., 2:3]
    a = [JOINT_INDEX[n] for n in ankles]
    assert np.abs(out[:, a] - model[:, a]).max() < 1e-9
    moved = np.linalg.norm(out[:, a] - points[:, a], axis=-1)
    assert 0.55 < np.median(moved) < 1.25 and 2.8 < moved.max() < 6.3  # measured 0.84 / 4.19 px
    rest = [j for j in range(16) if j not in a]
    np.testing.assert_array_equal(out[:, rest], points[:, rest])
