"""filter.kalman: removes measurement noise, the RTS smoother has no lag, untracked samples follow the model."""
from __future__ import annotations

import numpy as np

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.filter.kalman import kalman, kalman_smooth


def test_smoother_reduces_noise_on_a_moving_joint_without_lag():
    fps = 30.0
    t = np.arange(300) / fps
    truth = 0.3 * np.sin(2 * np.pi * 0.8 * t)  # 0.8 Hz swing, 0.3 m
    noisy = truth + np.random.default_rng(1).normal(0, 0.01, t.size)
    sm = kalman_smooth(noisy[:, None], fps, accel_sigma=20.0, measurement_sigma=0.01)[:, 0]
    causal = kalman_smooth(noisy[:, None], fps, accel_sigma=20.0, measurement_sigma=0.01, smooth=False)[:, 0]
    rms = lambda e: float(np.sqrt(np.mean(e[10:-10] ** 2)))
    assert rms(sm - truth) < 0.6 * rms(noisy - truth)
    lag = lambda y: int(np.argmax(np.correlate(np.gradient(y), np.gradient(truth), "full")) - (t.size - 1))
    assert lag(sm) == 0 and lag(causal) >= 0


def test_untracked_samples_follow_the_prediction():
    fps = 30.0
    x = np.linspace(0, 1, 60)  # constant velocity 0.5 m/s
    meas = x.copy()
    meas[30:35] += 0.2  # an outlier burst on untracked frames
    joints = np.zeros((60, 16, 3))
    joints[:, :, 0] = meas[:, None]
    tracked = np.ones((60, 16), bool)
    tracked[30:35] = False
    out = run_node(kalman, {"untracked_factor": 50.0}, motion={"joints": joints, "fps": np.array(fps), "tracked": tracked})["motion"]
    assert np.abs(out["joints"][30:35, 0, 0] - x[30:35]).max() < 0.03
    assert out["tracked"].shape == (60, 16)
