"""Suite-wide: the order in which pytest-xdist hands the test files to its workers.

``python -m pytest`` runs the files on every CPU (``-n logical --dist loadfile --no-loadscope-reorder`` in
pyproject.toml): each file goes whole to one worker, so a module's fixtures (a rendered take, a pipeline run) are
built once, and the files are handed out in collection order as workers come free. A file that takes a large share
of the suite (the solver on three renders: about half of it) must therefore start first, or a worker would pick it
up late while the other ran out of work. Listed heaviest first, as ``--durations`` measured them; any file not
listed keeps pytest's order after them. ``python -m pytest -n 0`` runs everything in one process, in this order.
"""
from __future__ import annotations

#: test files (relative to tests/) that start before all others, heaviest first: the 2026-11-29 CI run's
#: --durations, on 2 cores: test_solver_renders 2,200 s of 4,500, then test_solve_take ~550, test_studies_run ~250,
#: test_pipelines_run ~230, test_default_pipeline ~180, test_mediapipe_pipeline ~210
HEAVY_FIRST = (
    "mocap/test_solver_renders.py",
    "mocap/test_solve_take.py",
    "integration/test_studies_run.py",
    "integration/test_pipelines_run.py",
    "mocap/test_mediapipe_pipeline.py",
    "mocap/test_default_pipeline.py",
)


def pytest_collection_modifyitems(config, items):
    """Stable sort: the HEAVY_FIRST files' tests first (in that order), every other test after them as collected."""
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    tests_dir = config.rootpath / "tests"

    def key(item):
        try:
            rel = item.path.relative_to(tests_dir).as_posix()
        except ValueError:  # a test outside tests/ (a path given on the command line)
            return len(rank)
        return rank.get(rel, len(rank))

    items.sort(key=key)
