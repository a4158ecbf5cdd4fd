"""What the BVH holds against what the solver found, on the sweep's sixteen renders (``bench/solver_sweep.py``'s
takes: the sample, three CMU clips from other cameras, twelve turning takes in both suit kinds).

The default pipeline runs on each take (its nodes from the user cache, run where missing: the first run solves
every take, ~20 s each); for the solver's joints (``smooth.motion``) and the exported ones (``joints.joints3d``,
where the BVH puts them) in three variants of ``rotations``: ``export_swung`` (the torso's reference vectors matched
exactly, every limb bone swung: ``torso_fit`` and ``feet_reach`` off), ``export_reach`` (the knees bent so the
ankles land on the solver's: ``feet_reach`` on) and ``export_fit`` (the default: the torso fitted by least squares
too, ``torso_fit``), it prints per take and as means over the takes (``name=value``):

* ``*_seq_mm``: seq-MPJPE (one rigid alignment of the whole take, no scale), ``*_pa_mm``: PA-MPJPE (per frame,
  similarity), both against the render's truth;
* ``*_floor_mm`` / ``*_skate_mm``: the worst ankle below the floor and the planted ankles' sliding
  (``evaluate.metrics``' ``floor_penetration_mm`` / ``foot_skate_mm``), no truth needed.

    python bench/export_fidelity.py [--takes sample,walk131_01_f500_low]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from solver_sweep import SOLVER_TAKES, TURNING, take_graph  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.core.runner import run_graph  # noqa: E402
from tbha_graph.mocap.evaluate.measures import align_clip, procrustes_per_frame  # noqa: E402
from tbha_graph.mocap.evaluate.metrics import floor_figures  # noqa: E402

#: ``rotations`` params of each exported variant
ROTATIONS = {"export_swung": {"feet_reach": False, "torso_fit": False}, "export_reach": {"feet_reach": True, "torso_fit": False},
             "export_fit": {"feet_reach": True, "torso_fit": True}}
VARIANTS = ("motion", *ROTATIONS)


def figures(joints: np.ndarray, truth: np.ndarray, fps: float) -> dict:
    """seq / PA-MPJPE (mm) against ``truth`` and the floor figures of ``joints`` ``(n, 16, 3)`` metres."""
    aligned, _ = align_clip(joints, truth, mode="rigid")
    floor = floor_figures(joints, fps)
    return {"seq_mm": float(np.linalg.norm(aligned - truth, axis=-1).mean() * 1000),
            "pa_mm": float(np.linalg.norm(procrustes_per_frame(joints, truth) - truth, axis=-1).mean() * 1000),
            "floor_mm": floor["floor_penetration_mm"], "skate_mm": floor["foot_skate_mm"]}


def score(take, cache: Cache) -> dict[str, dict]:
    """``{variant: figures}`` of one take (:data:`VARIANTS`)."""
    out = {}
    for variant, params in ROTATIONS.items():
        graph, truth_ref = take_graph(take, node_sets={f"rotations.{k}": v for k, v in params.items()})
        run = run_graph(graph, outputs=["smooth", "joints", truth_ref.split(".")[0]], cache=cache)
        motion = run.output("smooth.motion")
        joints = np.asarray(motion["joints"], dtype=np.float64)
        truth = np.asarray(run.output(truth_ref)["joints3d_world"], dtype=np.float64)[: len(joints)]
        fps = float(motion["fps"])
        if "motion" not in out:
            out["motion"] = figures(joints, truth, fps)
        out[variant] = figures(np.asarray(run.output("joints.joints3d")["joints"], dtype=np.float64), truth, fps)
    return out


def main() -> None:
    every = ["sample"] + [t[0] for t in SOLVER_TAKES] + TURNING
    names = {t if isinstance(t, str) else "_".join(t): t for t in every}
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--takes", default=None, help=f"comma-separated, of {', '.join(names)} (default: all sixteen)")
    args = ap.parse_args()
    chosen = list(names) if args.takes is None else args.takes.split(",")
    if unknown := [n for n in chosen if n not in names]:
        ap.error(f"--takes: unknown {unknown}")
    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    rows = []
    for name in chosen:
        row = score(names[name], cache)
        rows.append(row)
        for variant, figs in row.items():
            for key, value in figs.items():
                print(f"{name}_{variant}_{key}={value:.2f}")
        sys.stdout.flush()
    for variant in VARIANTS:
        for key in rows[0][variant]:
            print(f"mean_{variant}_{key}={np.mean([r[variant][key] for r in rows]):.2f}")


if __name__ == "__main__":
    main()
