"""Renders for the MediaPipe benchmarks, made by the project's renderer (``pipelines/synthetic.yaml``) and kept
in a folder (default ``$TBHA_MP_RENDERS`` or ``~/.cache/tbha-graph/mp_renders``) so MediaPipe and the
solver can be re-run without re-rendering. A render is re-made when its folder lacks a finished manifest.

Two disjoint sets:

* ``EVAL``: what ``bench/mediapipe_compare.py`` scores: the bundled sample (131_02 walk, f = 700 px) and the
  three takes of ``bench/solver_accuracy.py`` (first 5 s of 131_01, 131_03, 131_02 with other cameras).
* ``FIT``: what ``bench/mediapipe_offsets_fit.py`` fits the landmark offsets on: the *later* parts of the
  full CMU clips (from 6 s on, ``/work/shared/mocap`` or ``$TBHA_CMU_FULL``: the bundled clips stop at 6 s),
  with an extra turn so the actor is seen from many sides, and cameras unlike the EVAL ones.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "data" / "mocap" / "cmu"
FULL = Path(os.environ.get("TBHA_CMU_FULL", "/work/shared/mocap/cmu"))

#: name -> (clip file, synthetic.yaml --set overrides). Camera eye/target metres, focal px, 640x480 30 fps.
EVAL: dict[str, tuple[Path, dict]] = {
    "sample": (BUNDLED / "131_02.bvh", {}),  # exactly data/sample (pipelines/synthetic.yaml defaults)
    "walk131_01_f500_low": (BUNDLED / "131_01.bvh", {"motion.duration": 5.0, "camera.eye": [-1.0, 0.9, 5.0],
                                                     "camera.target": [0.0, 0.9, 0.0], "camera.focal_px": 500.0}),
    "hop131_03_f1000_high": (BUNDLED / "131_03.bvh", {"motion.duration": 5.0, "camera.eye": [0.6, 1.8, 5.4],
                                                      "camera.target": [0.0, 0.8, 0.0], "camera.focal_px": 1000.0}),
    "walk131_02_f1200_far": (BUNDLED / "131_02.bvh", {"motion.duration": 5.0, "camera.eye": [1.2, 1.3, 6.0],
                                                      "camera.target": [0.0, 0.95, 0.0], "camera.focal_px": 1200.0}),
}
FIT: dict[str, tuple[Path, dict]] = {
    "fit_131_01": (FULL / "131_01.bvh", {"motion.start": 6.0, "motion.turn_degrees": 200.0, "motion.turn_start": 0.3,
                                         "motion.turn_seconds": 2.0, "camera.eye": [1.5, 1.2, 4.5], "camera.focal_px": 800.0}),
    "fit_131_02": (FULL / "131_02.bvh", {"motion.start": 6.0, "motion.turn_degrees": -220.0, "motion.turn_start": 0.3,
                                         "motion.turn_seconds": 3.5, "camera.eye": [-1.0, 1.6, 5.0], "camera.focal_px": 900.0}),
    "fit_131_03": (FULL / "131_03.bvh", {"motion.start": 6.0, "motion.turn_degrees": 120.0, "motion.turn_start": 0.3,
                                         "motion.turn_seconds": 2.5, "camera.eye": [0.3, 1.0, 4.0], "camera.focal_px": 650.0}),
}


def renders_dir() -> Path:
    return Path(os.environ.get("TBHA_MP_RENDERS", Path.home() / ".cache" / "tbha-graph" / "mp_renders"))


def _fmt(v) -> str:
    return "[" + ", ".join(str(x) for x in v) + "]" if isinstance(v, (list, tuple)) else str(v)


def render(name: str) -> Path:
    """The folder holding ``sample.mp4`` and ``ground_truth.npz`` of render ``name`` (made if missing)."""
    if name == "sample":
        return ROOT / "data" / "sample"
    clip, sets = {**EVAL, **FIT}[name]
    if not clip.is_file():
        raise SystemExit(f"{name}: clip {clip} not found (set TBHA_CMU_FULL to the full CMU clips' folder)")
    out = renders_dir() / name
    if (out / "manifest.json").is_file() and (out / "sample.mp4").is_file() and (out / "ground_truth.npz").is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "tbha_graph.cli.run", str(ROOT / "pipelines" / "synthetic.yaml"), "--var", f"bvh={clip}",
           "--out", str(out), "-q"]
    for k, v in sets.items():
        cmd += ["--set", f"{k}={_fmt(v)}"]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"{name}: render failed: {run.stderr.strip()[-800:]}")
    return out
