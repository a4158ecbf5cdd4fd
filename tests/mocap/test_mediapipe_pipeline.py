"""pipelines/mediapipe.yaml with real MediaPipe (the mediapipe extra) on the first 3 s of the bundled sample:
ordinary video in, BVH and metrics out. Bounds are about 1.5x what is measured — and what is measured is
poor (issue 16 is not resolved): MediaPipe's landmarks are taken as joint centres, their offsets from our
joints are not modelled yet."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tbha_graph.mocap.io.bvh import read_bvh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_keypoints import require_mediapipe  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def test_mediapipe_pipeline_runs_on_the_sample(tmp_path):
    require_mediapipe()
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "tbha_graph.cli.run", str(ROOT / "pipelines" / "mediapipe.yaml"),
                           "--set", "decode.stop=90", "--set", "truth.stop=90", "--out", str(out),
                           "--cache-dir", str(tmp_path / "cache")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 90 and m["tracked_pct"] > 95  # MediaPipe finds the mannequin in every frame
    assert m["pa_mpjpe_mm"] < 200 and m["mpjpe_mm"] < 540  # measured 134.8 / 362.5
    assert read_bvh(out / "motion.bvh").n_frames == 90
