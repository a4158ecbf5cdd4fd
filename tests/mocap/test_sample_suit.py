"""Sampling a suit's real colours from a take's T-pose frames (issue 14, item 12)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tbha_graph.mocap.color.sample_suit import main
from tbha_graph.mocap.suit import load_suit

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "data" / "sample" / "sample.mp4"


def _rgb(hx: str) -> np.ndarray:
    return np.array([int(hx[i : i + 2], 16) for i in (1, 3, 5)], dtype=float)


def _tinted_copy(path: Path, gains_bgr: tuple[float, float, float], n: int = 12) -> Path:
    cap = cv2.VideoCapture(str(SAMPLE))
    w = None
    for _ in range(n):
        ok, f = cap.read()
        assert ok
        if w is None:
            w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (f.shape[1], f.shape[0]))
        w.write(np.clip(f.astype(np.float32) * np.float32(gains_bgr), 0, 255).astype(np.uint8))
    w.release()
    cap.release()
    return path


def test_sampled_colours_are_the_videos_not_the_nominal_ones(tmp_path, capsys):
    plain = _tinted_copy(tmp_path / "plain.mp4", (1.0, 1.0, 1.0))
    warm = _tinted_copy(tmp_path / "warm.mp4", (0.88, 1.0, 1.0))  # less blue, as under warm light
    assert main([str(plain), "--frames", "0:12", "--out", str(tmp_path / "plain.yaml")]) == 0
    assert main([str(warm), "--frames", "0:12", "--out", str(tmp_path / "warm.yaml")]) == 0
    nominal, a, b = load_suit(), load_suit(tmp_path / "plain.yaml"), load_suit(tmp_path / "warm.yaml")
    assert a.patches == nominal.patches and set(a.colors) == set(nominal.colors)
    assert a.colors != nominal.colors  # measured, not copied
    for name in nominal.colors:  # the render's shading keeps each colour near its nominal value
        assert np.abs(_rgb(a.colors[name]) - _rgb(nominal.colors[name])).max() < 40, name
    # the warm take's blue channel is ~0.88 of the plain take's, red and green unchanged
    for name in ("blue", "cyan", "magenta", "purple"):
        ratio = _rgb(b.colors[name]) / np.maximum(_rgb(a.colors[name]), 1)
        assert abs(ratio[2] - 0.88) < 0.05 and abs(ratio[0] - 1.0) < 0.06, (name, ratio)


def test_an_existing_file_is_never_overwritten(tmp_path, capsys):
    target = tmp_path / "mine.yaml"
    target.write_text("my own notes")
    assert main([str(SAMPLE), "--frames", "0:5", "--out", str(target)]) == 2
    assert "exists; nothing was written" in capsys.readouterr().err
    assert target.read_text() == "my own notes"
    assert main([str(SAMPLE), "--frames", "5:2", "--out", str(tmp_path / "x.yaml")]) == 2
