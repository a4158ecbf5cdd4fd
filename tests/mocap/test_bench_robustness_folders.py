"""``bench/render_robustness.py --keep DIR --set ...``: runs with different settings go to different folders, so a
second setting never replaces the first's run (it did until round 21: both went to ``run_set/``)."""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from render_robustness import set_suffix  # noqa: E402


def test_each_setting_has_its_own_run_folder():
    assert set_suffix([]) == ""
    a = set_suffix(["reconstruct.sigma_px=1.5"])
    b = set_suffix(["reconstruct.sigma_px=2.0"])
    assert a.startswith("_set_") and len(a) == len("_set_") + 8 and a != b
    both = ["reconstruct.sigma_px=1.5", "track.gate_px=9"]
    assert set_suffix(both) == set_suffix(both[::-1]) != a  # order-free, and not the single setting's
