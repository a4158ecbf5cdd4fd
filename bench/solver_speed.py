"""Speed and memory of ``reconstruct.solve_take`` on the bundled sample's tracks and on a take 10x longer
(the sample's tracks played forwards and backwards, so the motion stays continuous).

Prints ``name=value`` lines: ``solver_ms_per_frame_sample``, ``solver_ms_per_frame_10x`` (the median of 3 solves
of the sample, 1 of the long take, after a first one), ``solver_first_solve_ms_per_frame_*`` (that first solve: the
first in the process also pays one-time imports and first calls, about 0.8 s), ``peak_mb_sample``, ``peak_mb_10x``
(peak traced Python allocations during one more solve) and the frame counts, as the default pipeline solves: the
actor's silhouette (``segment.silhouette``) connected and the focal length from the room's lines
(``calibrate.vanishing_points``: one start). ``..._no_silhouette``: the same without the silhouette (a pipeline
without the ``silhouette`` node, e.g. keypoints from a file); ``..._take_alone``: with the silhouette but without
the room's focal length (three starting focal lengths and their cross seeds).

    python bench/solver_speed.py            # tracks from the default pipeline's cache (runs it once)
    python bench/solver_speed.py --set side_split_cos=null --cases sample   # a setting's cost, the sample alone
    (``--cases``: any of sample, 10x, sample_no_silhouette, 10x_no_silhouette, sample_take_alone, 10x_take_alone)
"""
from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.core.runner import load_graph, run_graph  # noqa: E402
from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.bundles.lens import LensEstimate  # noqa: E402,F401 - named in an annotation
from tbha_graph.mocap.reconstruct.solve_take import SolveTakeParams, silhouette_field, solve_take_arrays  # noqa: E402


def sample_tracks() -> tuple[dict, "LensEstimate | None", dict]:
    """The sample's tracks (the default pipeline's, from the user cache), the room's focal length and floor
    (the ``lens`` the pipeline passes to the solver; None if the room gave none) and the actor's silhouette
    (``SILHOUETTE`` port value)."""
    g = load_graph(ROOT / "pipelines" / "default.yaml")
    run = run_graph(g, outputs=["track", "lens", "silhouette"], cache=Cache(Path.home() / ".cache" / "tbha-graph"))
    tr, lens = run.output("track.tracks"), run.output("lens.lens")
    sil = {k: np.asarray(v) for k, v in run.output("silhouette.silhouette").items()}
    return {k: np.asarray(v) for k, v in tr.items()}, (lens if lens.focal_px is not None else None), sil


def timed(points, tracked, width, height, fps, lens, silhouette: dict | None, repeats: int = 3,
          params: dict | None = None) -> tuple[float, float, float]:
    """Wall seconds of the first solve (untraced; the first in the process also pays the one-time imports and
    first calls: about 0.8 s on the sample), the median of ``repeats`` more (the per-frame cost proper), and the
    peak traced allocations of one more, identical solve (MB; tracing slows numpy code about 1.7x)."""
    def solve():
        t0 = time.perf_counter()  # the field is built inside the timing: the node builds it too
        sil = None if silhouette is None else silhouette_field(silhouette, len(points))
        solve_take_arrays(points, tracked, body_lengths(None), width, height, fps, SolveTakeParams(**(params or {})), lens=lens,
                          silhouette=sil)
        return time.perf_counter() - t0

    first = solve()
    median = float(np.median([solve() for _ in range(repeats)]))
    tracemalloc.start()
    solve()
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return first, median, peak


#: the solves timed, named as their figures' suffixes: take (sample, 10x) and setting ("", no_silhouette, take_alone)
CASES = tuple(f"{take}{suffix}" for suffix in ("", "_no_silhouette", "_take_alone") for take in ("sample", "10x"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a reconstruct.solve_take param (YAML value), repeatable")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    args = ap.parse_args()
    from solver_sweep import solver_sets  # bench/ is on the path (this script's folder)

    try:
        params = solver_sets(args.set)
    except ValueError as e:
        ap.error(str(e))
    cases = args.cases.split(",")
    if unknown := [c for c in cases if c not in CASES]:
        ap.error(f"--cases: unknown {unknown}; known: {', '.join(CASES)}")
    tr, lens, sil = sample_tracks()
    pts, trk = tr["points"], tr["tracked"]
    w, h, fps = int(tr["width"]), int(tr["height"]), float(tr["fps"])
    forth_back = lambda a: np.concatenate([a if k % 2 == 0 else a[::-1] for k in range(10)])  # noqa: E731
    long_pts, long_trk = forth_back(pts), forth_back(trk)
    per_frame = {k: v for k, v in sil.items() if v.ndim and len(v) == len(pts)}
    long_sil = {**sil, **{k: forth_back(v) for k, v in per_frame.items()}}
    print(f"frames_sample={len(pts)}")
    print(f"frames_10x={len(long_pts)}")
    print(f"room_focal_px={lens.focal_px if lens else None}")
    for suffix, prior, with_sil in (("", lens, True), ("_no_silhouette", lens, False), ("_take_alone", None, True)):
        for name, p, t, s in (("sample", pts, trk, sil), ("10x", long_pts, long_trk, long_sil)):
            if f"{name}{suffix}" not in cases:
                continue
            first, dt, peak = timed(p, t, w, h, fps, prior, s if with_sil else None,
                                    repeats=3 if name == "sample" else 1, params=params)
            print(f"solver_ms_per_frame_{name}{suffix}={1000 * dt / len(p):.1f}")
            print(f"solver_first_solve_ms_per_frame_{name}{suffix}={1000 * first / len(p):.1f}")
            print(f"peak_mb_{name}{suffix}={peak:.1f}", flush=True)


if __name__ == "__main__":
    main()
