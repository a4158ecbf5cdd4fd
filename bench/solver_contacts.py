"""How well ``reconstruct.solve_take`` finds planted feet from the image (:func:`.solve_take.contacts_from_image`),
against each render's own stances, on the sixteen renders of ``bench/solver_sweep.py``.

A stance frame of the truth: the ankle joint moves under ``STANCE_SPEED`` (0.35 m/s, the slower of its steps to the
two neighbouring frames) and lies within ``STANCE_BAND`` (4 cm) of its lowest height over the take (its 5th
percentile), on a frame where the tracker has the ankle's point. Prints per take ``<take>_recall=`` (stance frames
found), ``<take>_precision=`` (found frames that are stance frames) and ``<take>_false=`` (found frames that are
not), each ankle counted per frame; then ``all16_recall``, ``all16_precision`` (means over the takes) and
``all16_false`` (the sum). Inputs come from the default pipeline's nodes in the user cache (run where missing).

    python bench/solver_contacts.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from solver_accuracy import TAKES as SOLVER_TAKES  # noqa: E402
from solver_sweep import TURNING, solver_inputs  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.mocap.reconstruct.solve_take import ANKLES, contacts_from_image  # noqa: E402

#: A truth ankle slower than this (m/s) ...
STANCE_SPEED = 0.35
#: ... and within this (m) of its lowest height is planted
STANCE_BAND = 0.04


def truth_stance(joints: np.ndarray, fps: float) -> np.ndarray:
    """Planted ankles ``(n, 2)`` bool of the truth's world joints ``(n, 16, 3)`` (metres, y up)."""
    ank = joints[:, ANKLES]
    n = ank.shape[0]
    speed = np.zeros((n, 2))
    if n > 1:
        step = np.linalg.norm(np.diff(ank, axis=0), axis=-1) * fps
        speed[0], speed[-1] = step[0], step[-1]
        speed[1:-1] = np.minimum(step[1:], step[:-1])
    h = ank[..., 1]
    return (speed < STANCE_SPEED) & (h < np.percentile(h, 5, axis=0) + STANCE_BAND)


def main() -> None:
    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    recall, precision, false = [], [], 0
    for take in ["sample"] + [t[0] for t in SOLVER_TAKES] + TURNING:
        name = take if isinstance(take, str) else f"{take[0]}_{take[1]}"
        tr, truth, *_ = solver_inputs(take, cache)
        fps = float(tr.fps)
        want = truth_stance(np.asarray(truth["joints3d_world"], dtype=np.float64)[:tr.n_frames], fps)
        want &= tr.tracked[:, ANKLES]
        got = contacts_from_image(tr.points, tr.tracked, fps)
        hit = int((got & want).sum())
        recall.append(hit / max(int(want.sum()), 1))
        precision.append(hit / max(int(got.sum()), 1))
        false += int((got & ~want).sum())
        print(f"{name}_recall={recall[-1]:.3f}", f"{name}_precision={precision[-1]:.3f}",
              f"{name}_false={int((got & ~want).sum())}", sep="\n", flush=True)
    print(f"all16_recall={np.mean(recall):.3f}", f"all16_precision={np.mean(precision):.3f}", f"all16_false={false}",
          sep="\n")


if __name__ == "__main__":
    main()
