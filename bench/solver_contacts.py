"""How well ``reconstruct.solve_take`` finds planted feet from the image (:func:`.solve_take.contacts_from_image`),
against each render's own stances, on the sixteen renders of ``bench/solver_sweep.py``.

A stance frame of the truth: an ankle ``filter.foot_contact`` finds planted on the truth's own joints (its
``detect_contacts`` with its default params: smoothed speed under 0.3 m/s, within 5 cm of the ankles' 5th-percentile
height, contacts of at least 0.1 s), on a frame where the tracker has the ankle's point. Prints per take ``<take>_recall=`` (stance frames
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
from tbha_graph.mocap.filter.foot_contact import FootContactParams, detect_contacts, floor_height  # noqa: E402
from tbha_graph.mocap.reconstruct.solve_take import ANKLES, contacts_from_image  # noqa: E402


def truth_stance(joints: np.ndarray, fps: float) -> np.ndarray:
    """Planted ankles ``(n, 2)`` bool (left, right) of the truth's world joints ``(n, 16, 3)`` (metres, y up), as
    ``filter.foot_contact`` finds them."""
    p = FootContactParams()
    c = detect_contacts(joints, fps, p, floor_height(joints, p.floor_percentile))
    return np.stack([c["left"], c["right"]], axis=1)


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
        hit, wrong = int((got & want).sum()), int((got & ~want).sum())
        recall.append(hit / max(int(want.sum()), 1))
        precision.append(hit / max(int(got.sum()), 1))
        false += wrong
        print(f"{name}_recall={recall[-1]:.3f}", f"{name}_precision={precision[-1]:.3f}", f"{name}_false={wrong}",
              sep="\n", flush=True)
    print(f"all16_recall={np.mean(recall):.3f}", f"all16_precision={np.mean(precision):.3f}", f"all16_false={false}",
          sep="\n")


if __name__ == "__main__":
    main()
