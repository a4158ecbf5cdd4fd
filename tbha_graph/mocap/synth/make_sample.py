"""Regenerate the bundled sample: ``python -m tbha_graph.mocap.synth.make_sample data/sample``.

Does what ``pipelines/synthetic.yaml`` does, without the pipeline runner: the trimmed CMU clip 131_02
(walk) opened by a 1 s T-pose and a 0.5 s blend (``synth.tpose_lead_in``), the default camera
(``synth.camera``), rendered at 640x480, 30 fps, seed 0 (``synth.render_suit_video``). Writes
``sample.mp4`` and ``ground_truth.npz`` into the folder (atomically; other files there are kept).
Deterministic: the same code gives the same files.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ...core.atomic import atomic_path
from ..camera import Camera
from ..suit import load_suit
from .camera import CameraParams
from .render import RenderParams, render_video
from .tpose_lead_in import LeadInParams, lead_in_motion

DEFAULT_BVH = Path(__file__).resolve().parents[3] / "data" / "mocap" / "cmu" / "131_02.bvh"


def make_sample(out_dir: Path, bvh: Path = DEFAULT_BVH, seed: int = 0) -> tuple[Path, Path]:
    """Render the sample into ``out_dir``; returns the paths of the video and the ground truth."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    joints, fps = lead_in_motion(LeadInParams(path=bvh, hold_seconds=1.0, blend_seconds=0.5))
    cp = CameraParams()
    cam = Camera.look_at(cp.eye, cp.target, focal_px=cp.focal_px, width=cp.width, height=cp.height)
    video = out_dir / "sample.mp4"
    gt = render_video(joints, fps, cam, load_suit(), RenderParams(seed=seed), video)
    npz = out_dir / "ground_truth.npz"
    with atomic_path(npz) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **gt)
    return video, npz


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description="Render the bundled tight-suit sample video and its ground truth.")
    ap.add_argument("out_dir", type=Path, help="folder to write sample.mp4 and ground_truth.npz into")
    ap.add_argument("--bvh", type=Path, default=DEFAULT_BVH, help="BVH clip (CMU skeleton)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    for p in make_sample(args.out_dir, args.bvh, args.seed):
        print(f"{p}  {p.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
