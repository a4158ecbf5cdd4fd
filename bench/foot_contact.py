"""Benchmark: filter.foot_contact on the CMU walks. Prints ``name=value`` lines.

Each walk (131_01, 131_02; 120 fps taken every 4th frame: 30 fps, the video rate) gets Gaussian noise
of ``sigma`` metres per coordinate added to both ankles (seed 0), then runs through the node with its
default params (``mode: auto``):

* ``sliding_before_mm_<clip>_<sigma mm>`` / ``sliding_after_mm_...``: mean horizontal ankle displacement
  between consecutive frames both in contact, millimetres per contact frame, before / after locking
  (the same detected contacts for both).
* ``contact_agreement_<clip>_<sigma mm>``: fraction of frames (both feet) whose contact label on the
  noisy clip equals the label on the clean clip.
* ``ik_clamped_frames_...``: frames whose locked target was out of the leg's reach.
* ``us_per_frame``: node time per frame on 131_02 tiled to 10,000 frames at 1 cm noise (median of 5).

Run: ``python bench/foot_contact.py``.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.filter.foot_contact import FootContactParams, detect_contacts, floor_height, foot_contact
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh

DATA = Path(__file__).resolve().parents[1] / "data" / "mocap" / "cmu"
CLIPS = ("131_01", "131_02")
SIGMAS_M = (0.0, 0.005, 0.01, 0.02)
FPS = 30.0
ANKLES = [12, 15]


def noisy(joints: np.ndarray, sigma: float, seed: int = 0) -> np.ndarray:
    out = joints.copy()
    out[:, ANKLES] += np.random.default_rng(seed).normal(0.0, sigma, size=(out.shape[0], 2, 3))
    return out


def main() -> None:
    p = FootContactParams()
    for clip in CLIPS:
        clean = motion16_from_bvh(DATA / f"{clip}.bvh")["joints"][::4].copy()
        ref = detect_contacts(clean, FPS, p, floor_height(clean, p.floor_percentile))
        for sigma in SIGMAS_M:
            j = noisy(clean, sigma)
            rep = run_node(foot_contact, {}, motion={"joints": j, "fps": np.asarray(FPS)})["report"]
            got = detect_contacts(j, FPS, p, floor_height(j, p.floor_percentile))
            agree = float(np.mean([np.mean(ref[s] == got[s]) for s in ref]))
            tag = f"{clip}_{sigma * 1000:g}mm"
            print(f"sliding_before_mm_{tag}={rep['foot_sliding_before_mm']:.3f}")
            print(f"sliding_after_mm_{tag}={rep['foot_sliding_after_mm']:.4f}")
            print(f"contact_agreement_{tag}={agree:.3f}")
            print(f"ik_clamped_frames_{tag}={rep['ik_clamped_frames']}")
    walk = motion16_from_bvh(DATA / "131_02.bvh")["joints"][::4]
    big = noisy(np.tile(walk, (int(np.ceil(10_000 / len(walk))), 1, 1))[:10_000], 0.01)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        run_node(foot_contact, {}, motion={"joints": big, "fps": np.asarray(FPS)})
        times.append(time.perf_counter() - t0)
    print(f"us_per_frame={statistics.median(times) / len(big) * 1e6:.2f}")


if __name__ == "__main__":
    main()
