"""``bench/solver_sweep.py --against FILE``: an earlier run's figures read back, each take's delta and the running
count of takes worse than before, and a file that is not a sweep's output refused naming it."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sweep():
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        yield importlib.import_module("solver_sweep")
    finally:
        sys.path.remove(str(ROOT / "bench"))


def test_deltas_and_the_count_of_worse_takes(sweep, tmp_path):
    base = tmp_path / "base.txt"
    base.write_text("sample_mpjpe_mm=50.9\nsample_mpjpe_mm_min=48.9\nhop_mpjpe_mm=42.0\nINFO: a log line\n"
                    "all16_mean_mm=89.3\nall16_ms_per_frame=71.6\n")
    before = sweep.read_figures(base)
    assert before == {"sample_mpjpe_mm": 50.9, "hop_mpjpe_mm": 42.0, "all16_mean_mm": 89.3}
    worse: list[bool] = []
    assert sweep.compared("sample", 54.7, before, worse) == ["sample_delta_mm=+3.8", "worse_so_far=1/1"]
    assert sweep.compared("hop", 39.9, before, worse) == ["hop_delta_mm=-2.1", "worse_so_far=1/2"]
    assert sweep.compared("new_take", 70.0, before, worse) == [] and len(worse) == 2  # not in the earlier run
    assert sweep.compared("all16_mean", 88.0, before, None) == ["all16_mean_delta_mm=-1.3"]


def test_a_file_that_is_not_a_sweeps_output_is_refused_naming_it(sweep, tmp_path, capsys):
    other = tmp_path / "ci.log"
    other.write_text("668 passed\n")
    with pytest.raises(SystemExit):
        sweep.main(["--against", str(other)])
    assert f"--against: {other}: no 'sample_mpjpe_mm=' line" in capsys.readouterr().err
