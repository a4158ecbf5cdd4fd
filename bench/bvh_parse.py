"""Benchmark: BVH parsing and forward kinematics on a real CMU clip. Prints ``name=value`` lines.

Parses the BVH file given as the argument, by default the project's copy of CMU 131_02
(``data/mocap/cmu/131_02.bvh``, 720 frames, 31 joints). Figures are medians over repeats.
Run: ``python bench/bvh_parse.py [FILE.bvh]``.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from tbha_graph.mocap.io.bvh import bvh_positions, bvh_to_local, read_bvh, write_bvh
from tbha_graph.mocap.kinematics import forward_kinematics

BUNDLED = Path(__file__).resolve().parents[1] / "data" / "mocap" / "cmu" / "131_02.bvh"


def median_seconds(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bvh", nargs="?", type=Path, default=BUNDLED, help=f"BVH file to parse (default: {BUNDLED.name} in data/mocap/cmu)")
    path = ap.parse_args().bvh
    if not path.is_file():
        ap.error(f"{path} does not exist")
    bvh = read_bvh(path)
    local, root = bvh_to_local(bvh)
    n = bvh.n_frames
    print(f"bvh_file={path}")
    print(f"bvh_frames={n}")
    print(f"bvh_joints={len(bvh.joints)}")
    print(f"bvh_parse_ms={median_seconds(lambda: read_bvh(path), 15) * 1e3:.2f}")
    print(f"euler_to_quat_us_per_frame={median_seconds(lambda: bvh_to_local(bvh), 15) / n * 1e6:.2f}")
    fk = median_seconds(lambda: forward_kinematics(bvh.parents, bvh.offsets, local, root), 15)
    print(f"fk_us_per_frame={fk / n * 1e6:.2f}")
    print(f"bvh_positions_us_per_frame={median_seconds(lambda: bvh_positions(bvh), 15) / n * 1e6:.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.bvh"
        print(f"bvh_write_ms={median_seconds(lambda: write_bvh(out, bvh), 7) * 1e3:.2f}")


if __name__ == "__main__":
    main()
