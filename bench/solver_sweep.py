"""The whole-take solver alone on sixteen renders, to compare its settings on more than one take.

Any single take's seq-MPJPE swings by 30-50 mm with any change to the solver (near-tied depth-side and turn
choices flip), so a setting is judged here by the mean over sixteen takes: the bundled sample, the three
renders of ``bench/solver_accuracy.py`` and the twelve turning takes of ``bench/labelling.py`` (six and
the three held out, both suits). Each take's tracks, silhouette, room lines and truth come from the
default pipeline's nodes (cached in the user cache: the first run renders and tracks, about 10 minutes;
later runs only solve, about 2 minutes per setting); the solve is ``solve_take_arrays`` as the node runs it.

Prints ``name=value`` lines: ``<take>_mpjpe_mm`` (one rigid alignment over the whole take, no scale), then
``solver4_mean_mm`` (the sample and the three solver renders), ``turning12_mean_mm`` and ``all16_mean_mm``.

    python bench/solver_sweep.py                                  # the default settings, the room's focal length
    python bench/solver_sweep.py --set sigma_px=1.0               # a SolveTakeParams field changed
    python bench/solver_sweep.py --focal given                    # the true focal length given (focal_px)
    python bench/solver_sweep.py --focal take                     # no room lines: the focal length from the take
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import labelling  # noqa: E402  (the turning takes, one definition)
from solver_accuracy import TAKES as SOLVER_TAKES, render_graph  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.core.runner import load_graph, run_graph  # noqa: E402
from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.bundles.tracks import read_tracks  # noqa: E402
from tbha_graph.mocap.evaluate.measures import align_clip  # noqa: E402
from tbha_graph.mocap.reconstruct import solve_take as st  # noqa: E402

TURNING = [(take, suit) for take in list(labelling.TAKES) + list(labelling.HELD_OUT) for suit in labelling.SUITS]


def take_graph(take):
    """The default pipeline's graph for ``take`` (``"sample"``, a solver render's name, or a ``(take, suit)``
    turning take) and the output holding its ground truth."""
    if take == "sample":
        return load_graph(ROOT / "pipelines" / "default.yaml"), "truth.truth"
    if isinstance(take, str):
        return render_graph(next(t for t in SOLVER_TAKES if t[0] == take)), "render.ground_truth"
    sets, vars = labelling.take_config(*take)
    return load_graph(ROOT / "pipelines" / "evaluate_render.yaml", sets=sets, vars=vars), "render.ground_truth"


def solve(take, params: dict, focal: str, cache: Cache) -> float:
    """Seq-MPJPE (mm) of the solver on ``take`` with ``SolveTakeParams(**params)``; ``focal``: ``room`` (the
    ``lens`` node's estimate, as the default pipeline), ``given`` (the truth's) or ``take`` (no lens)."""
    graph, truth_ref = take_graph(take)
    run = run_graph(graph, outputs=["track", "silhouette", "lens", truth_ref.split(".")[0]], cache=cache)
    truth = run.output(truth_ref)
    tr = read_tracks(run.output("track.tracks"))
    n = tr.n_frames
    gt = np.asarray(truth["joints3d_world"])[:n]
    p = dict(params)
    if focal == "given":
        p["focal_px"] = float(np.asarray(truth["K"])[0, 0])
    res = st.solve_take_arrays(tr.points, tr.tracked, body_lengths(None), tr.width, tr.height, float(tr.fps),
                               st.SolveTakeParams(**p), silhouette=st.silhouette_field(run.output("silhouette.silhouette"), n),
                               lens=None if focal == "take" else run.output("lens.lens"))
    aligned, _ = align_clip(res["joints"], gt, mode="rigid")
    return float(np.linalg.norm(aligned - gt, axis=-1).mean() * 1000.0)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a reconstruct.solve_take param (YAML value), repeatable")
    ap.add_argument("--focal", choices=("room", "given", "take"), default="room")
    args = ap.parse_args(argv)
    params = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep or key not in st.SolveTakeParams.model_fields:
            ap.error(f"--set {item!r}: expected FIELD=VALUE with FIELD one of reconstruct.solve_take's params")
        params[key] = yaml.safe_load(value)
    try:  # a bad value fails here, before minutes of solving
        st.SolveTakeParams(**params)
    except ValueError as e:  # pydantic's ValidationError
        ap.error(f"--set: {e}")
    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    mm = {}
    for take in ["sample"] + [t[0] for t in SOLVER_TAKES] + TURNING:
        name = take if isinstance(take, str) else f"{take[0]}_{take[1]}"
        mm[name] = solve(take, params, args.focal, cache)
        print(f"{name}_mpjpe_mm={mm[name]:.1f}", flush=True)
    v = list(mm.values())
    print(f"solver4_mean_mm={np.mean(v[:4]):.1f}")
    print(f"turning12_mean_mm={np.mean(v[4:]):.1f}")
    print(f"all16_mean_mm={np.mean(v):.1f}")


if __name__ == "__main__":
    main()
