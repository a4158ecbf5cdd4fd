"""Fault tests of ``tbha-run`` on a small real pipeline (CMU BVH -> Butterworth -> quaternion
rotations -> export.bvh), each run as a separate process with its own ``TBHA_CACHE_DIR``:

* SIGKILL at known points of a run, not at guessed moments (which landed during start-up imports):
  the pipeline has two pass-through nodes of the test plugin :mod:`fault_nodes` that announce they
  started running (a marker file) and pause, and the plugin announces every cache store between the
  entry's payload and its ``meta.json``. The test waits for a marker and kills the process group at
  once: inside a node, or in the middle of storing a node's outputs (first, middle and last node),
  with the expected number of complete cache entries at that moment. Then the same command again: no
  cache entry is corrupt (every file matches the SHA-256 in its ``meta.json``), no run directory
  that looks complete holds anything else than the complete result, and the resumed run's
  ``motion.bvh`` is byte-identical to an uninterrupted run's.
* Two ``tbha-run`` processes of the same pipeline at once on one empty cache both succeed with
  identical outputs and a clean cache; eight runs at once (threads) into one run directory all
  succeed and leave one complete result.
* An output directory that cannot be written (under a regular file; on a read-only file system; on
  a full one) fails with a clear error naming the folder, exit code 2, and leaves no output behind.
  The last two need ``unshare -m`` + ``mount`` (a private mount namespace: nothing stays mounted);
  chmod is no test here because the suite runs as root, which ignores permissions.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "data" / "mocap" / "cmu" / "131_02.bvh"

PIPELINE = f"""\
description: CMU walk -> smoothed -> joint rotations -> BVH (fault tests)
nodes:
  load:
    type: io.bvh_load
    params: {{path: {CLIP}, mapping: cmu}}
  smooth:
    type: filter.butterworth
    inputs: {{motion: load.motion}}
    params: {{cutoff: 6.0, order: 4}}
  solve:
    type: rotations.quaternion
    inputs: {{motion: smooth.motion}}
  export:
    type: export.bvh
    inputs: {{rotations: solve.rotations}}
outputs:
  motion.bvh: export.bvh
"""
TBHA_RUN = [sys.executable, "-m", "tbha_graph.cli.run"]

#: the same work with two marker nodes of the test plugin fault_nodes (kill points inside nodes); it
#: extends PIPELINE written beside it as walk.yaml
MARKED_PIPELINE = """\
description: CMU walk -> smoothed -> joint rotations -> BVH, with kill points (fault tests)
extends: walk.yaml
nodes:
  mid: {type: fault.pause_motion, inputs: {motion: smooth.motion}, params: {label: mid}}
  solve: {inputs: {motion: mid.motion}}
  late: {type: fault.pause_rotations, inputs: {rotations: solve.rotations}, params: {label: late}}
  export: {inputs: {rotations: late.rotations}}
"""
MARKED_NODES = {"load", "smooth", "mid", "solve", "late", "export"}
#: where to kill (the marker that must appear first) and how many complete cache entries exist then;
#: stores happen in run order: load 0, smooth 1, mid 2, solve 3, late 4, export 5
KILL_POINTS = {
    "storing load's output (first node)": ("store-0.started", 0),
    "inside node mid": ("mid.started", 2),
    "storing solve's output (middle node)": ("store-3.started", 3),
    "inside node late": ("late.started", 4),
    "storing export's BVH (last node)": ("store-5.started", 5),
}


def run_cmd(pipeline: Path, out: Path, cache: Path, *extra: str) -> list[str]:
    return [*TBHA_RUN, str(pipeline), "--out", str(out), "--cache-dir", str(cache), "--quiet", *extra]


def env_for(cache: Path) -> dict[str, str]:
    return dict(os.environ, TBHA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")


def tbha_run(pipeline: Path, out: Path, cache: Path, timeout: float = 120, plugin: bool = False) -> subprocess.CompletedProcess:
    if plugin:
        return subprocess.run([*run_cmd(pipeline, out, cache), "--plugin", "fault_nodes"], capture_output=True, text=True,
                              timeout=timeout, env=plugin_env(cache), cwd=pipeline.parent)
    return subprocess.run(run_cmd(pipeline, out, cache), capture_output=True, text=True, timeout=timeout,
                          env=env_for(cache), cwd=pipeline.parent)


def check_cache(cache: Path) -> int:
    """Every entry's files match the SHA-256 in its meta.json; returns the number of entries."""
    n = 0
    for meta_path in sorted((cache / "entries").glob("*/*/meta.json")):
        meta = json.loads(meta_path.read_text())
        assert meta["key"] == meta_path.parent.name
        for port, info in meta["outputs"].items():
            data = (meta_path.parent / info["file"]).read_bytes()
            assert hashlib.sha256(data).hexdigest() == info["sha256"], f"corrupt cache entry {meta_path.parent.name}: {port}"
            assert len(data) == info["bytes"]
        n += 1
    for d in (cache / "entries").glob("*/*"):
        assert (d / "meta.json").is_file(), f"cache entry folder without meta.json: {d}"
    memo = cache / "filehash.json"
    if memo.exists():
        json.loads(memo.read_text())  # the file-hash memo is never half-written
    return n


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict:
    """An uninterrupted run: its motion.bvh bytes and how long the whole command took."""
    d = tmp_path_factory.mktemp("faults_ref")
    pipeline = d / "walk.yaml"
    pipeline.write_text(PIPELINE)
    t0 = time.perf_counter()
    proc = tbha_run(pipeline, d / "run", d / "cache")
    seconds = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr
    assert check_cache(d / "cache") == 4
    return {"bvh": (d / "run" / "motion.bvh").read_bytes(), "seconds": seconds, "pipeline": pipeline, "cache": d / "cache"}


def warm_cache(reference: dict, dest: Path) -> Path:
    """A copy of the reference run's cache (every node a cache hit: the run goes straight to writing)."""
    shutil.copytree(reference["cache"], dest)
    return dest


@pytest.fixture(scope="module")
def marked_reference(tmp_path_factory) -> dict:
    """An uninterrupted run of the pipeline with kill points (markers off): its motion.bvh bytes."""
    d = tmp_path_factory.mktemp("faults_marked_ref")
    (d / "walk.yaml").write_text(PIPELINE)
    pipeline = d / "walk_marked.yaml"
    pipeline.write_text(MARKED_PIPELINE)
    proc = subprocess.run([*run_cmd(pipeline, d / "run", d / "cache"), "--plugin", "fault_nodes"], capture_output=True,
                          text=True, timeout=120, env=plugin_env(d / "cache"), cwd=d)
    assert proc.returncode == 0, proc.stderr
    assert check_cache(d / "cache") == len(MARKED_NODES)
    return {"bvh": (d / "run" / "motion.bvh").read_bytes(), "pipeline": pipeline}


def plugin_env(cache: Path, markers: Path | None = None) -> dict[str, str]:
    """The environment of a run that can import the test plugin (and, with ``markers``, announces itself)."""
    env = env_for(cache)
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent), *filter(None, [env.get("PYTHONPATH")])])
    if markers is not None:
        env["TBHA_FAULT_MARKERS"] = str(markers)
    return env


@pytest.mark.parametrize("point", list(KILL_POINTS))
def test_sigkill_mid_run_then_resume(marked_reference, tmp_path, point) -> None:
    marker, entries_then = KILL_POINTS[point]
    pipeline, cache, out, markers = marked_reference["pipeline"], tmp_path / "cache", tmp_path / "run", tmp_path / "markers"
    markers.mkdir()
    cmd = [*run_cmd(pipeline, out, cache), "--plugin", "fault_nodes"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=plugin_env(cache, markers),
                            cwd=pipeline.parent, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (markers / marker).exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=30)
            pytest.fail(f"{marker} never appeared (exit {proc.poll()}): {proc.stderr.read().decode()[-2000:]}")
        time.sleep(0.002)
    os.killpg(proc.pid, signal.SIGKILL)  # the run is paused just after writing the marker: inside the node or store
    proc.wait(timeout=30)
    proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL, f"the run was not killed at {point} (exit {proc.returncode})"
    assert check_cache(cache) == entries_then if cache.exists() else entries_then == 0  # killed where intended
    assert not out.exists()  # killed before the run directory was written

    again = tbha_run(pipeline, out, cache, plugin=True)
    assert again.returncode == 0, again.stderr
    assert (out / "motion.bvh").read_bytes() == marked_reference["bvh"]
    assert check_cache(cache) == len(MARKED_NODES)
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["nodes"]) == MARKED_NODES
    ran = {n for n, info in manifest["nodes"].items() if info["status"] == "ran"}
    assert len(ran) == len(MARKED_NODES) - entries_then  # the entries stored before the kill are reused


def test_runs_at_once_on_one_cache(reference, tmp_path) -> None:
    pipeline, cache = reference["pipeline"], tmp_path / "cache"
    outs = [tmp_path / "run_a", tmp_path / "run_b"]
    procs = [subprocess.Popen(run_cmd(pipeline, o, cache), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env=env_for(cache), cwd=pipeline.parent) for o in outs]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    for p in procs:
        p.stderr.close()
    for rc, err in results:
        assert rc == 0, err
    for o in set(outs):
        assert (o / "motion.bvh").read_bytes() == reference["bvh"]
        assert json.loads((o / "manifest.json").read_text())["nodes"].keys() == {"load", "smooth", "solve", "export"}
    assert check_cache(cache) == 4
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".run"))
    assert not leftovers, f"staging folders left behind: {leftovers}"


def test_many_runs_into_one_run_dir_at_once(reference, tmp_path) -> None:
    """Eight threads x 10 rounds finishing together into one run directory (a warm cache, so they race
    on the final rename): none may fail, and the folder always holds one complete result. Before the
    fix in core/rundir.py about 1 in 16 failed with 'Directory not empty' or 'No such file'."""
    import threading

    from tbha_graph.core.cache import Cache
    from tbha_graph.core.runner import load_graph, run_graph

    graph = load_graph(reference["pipeline"])
    cache = Cache(warm_cache(reference, tmp_path / "cache"))
    out = tmp_path / "run"
    errors: list[str] = []
    for _ in range(10):
        barrier = threading.Barrier(8)

        def one() -> None:
            barrier.wait()
            try:
                run_graph(graph, out_dir=out, cache=cache)
            except Exception as e:  # noqa: BLE001 - collected and asserted below
                errors.append(repr(e))

        threads = [threading.Thread(target=one) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert (out / "motion.bvh").read_bytes() == reference["bvh"]
    assert not errors, errors
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "run"]


def _assert_clean_failure(proc: subprocess.CompletedProcess, folder_hint: str) -> None:
    assert proc.returncode == 2, f"exit {proc.returncode}: {proc.stderr}"
    err = proc.stderr
    assert "Traceback" not in err, err
    assert "error:" in err and folder_hint in err, err


def test_output_under_a_regular_file(reference, tmp_path) -> None:
    """In-process (the CLI prints this same TbhaError as 'error: ...', exit 2: see the mount tests)."""
    from tbha_graph.core.cache import Cache
    from tbha_graph.core.errors import TbhaError
    from tbha_graph.core.runner import load_graph, run_graph

    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a regular file\n")
    with pytest.raises(TbhaError, match="output folder") as info:
        run_graph(load_graph(reference["pipeline"]), out_dir=blocker / "run", cache=Cache(warm_cache(reference, tmp_path / "cache")))
    assert str(blocker) in str(info.value)
    assert blocker.read_text() == "a regular file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "not_a_folder"]
    check_cache(tmp_path / "cache")


def _mount_works() -> str:
    if not shutil.which("unshare") or not shutil.which("mount"):
        return "unshare/mount not available"
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt && umount /mnt"],
                           capture_output=True, text=True)
    return "" if probe.returncode == 0 else f"cannot mount a tmpfs in a private mount namespace here: {probe.stderr.strip()}"


@pytest.mark.parametrize("fs", ["read_only", "full"])
def test_output_on_unwritable_file_system(reference, tmp_path, fs) -> None:
    """``--out`` on a read-only tmpfs, or on a 64 KiB tmpfs (the BVH is ~350 KB: the disk fills up)."""
    reason = _mount_works()
    if reason:
        pytest.skip(reason)
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    cache = warm_cache(reference, tmp_path / "cache")
    opts = "ro,size=1m" if fs == "read_only" else "size=64k"
    cmd = " ".join(f"'{c}'" for c in run_cmd(reference["pipeline"], mnt / "run", cache))
    script = (f"mount -t tmpfs -o {opts} tmpfs '{mnt}' || exit 99\n"
              f"{cmd}\nrc=$?\necho \"LISTING:$(ls -A '{mnt}' | tr '\\n' ' ')\" >&2\nexit $rc\n")
    proc = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True, timeout=120,
                          env=env_for(cache), cwd=reference["pipeline"].parent)
    assert proc.returncode != 99, proc.stderr
    _assert_clean_failure(proc, str(mnt / "run"))
    listing = proc.stderr.rsplit("LISTING:", 1)[1].strip()
    assert listing == "", f"left behind on the output file system: {listing}"
    assert not any(mnt.iterdir())  # the mount is gone with its namespace; nothing was written below it
    assert check_cache(cache) == 4
