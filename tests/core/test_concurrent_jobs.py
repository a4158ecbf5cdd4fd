"""The local executor with several jobs (``run_graph(jobs=N)``, ``tbha-run --jobs N``): independent nodes run at
the same time, and everything else is as with one job — results, cache keys, warnings and their order, the
failing node named, a corrupt cache entry recomputed."""
from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import pytest
from testnodes import CHAIN

from tbha_graph.core.errors import NodeFailed
from tbha_graph.core.runner import load_graph, run_graph


def meeting(timeout: float = 5.0, warn_a: str = "", warn_b: str = "") -> str:
    """Two branches that each wait for the other to start (test.meet), joined by an add; a fresh group each call."""
    g = uuid.uuid4().hex
    return f"""
        nodes:
          src: {{type: test.source, params: {{n: 3, value: 1.0}}}}
          a: {{type: test.meet, inputs: {{x: src.x}}, params: {{group: "{g}", timeout: {timeout}, warn: "{warn_a}", factor: 2}}}}
          b: {{type: test.meet, inputs: {{x: src.x}}, params: {{group: "{g}", timeout: {timeout}, warn: "{warn_b}", factor: 3}}}}
          sum: {{type: test.add, inputs: {{a: a.y, b: b.y}}}}
        outputs: {{sum.npz: sum.y}}
    """


def test_two_jobs_run_independent_nodes_at_the_same_time(write, registry, cache):
    run = run_graph(load_graph(write("p.yaml", meeting()), registry=registry), cache=cache, jobs=2)
    np.testing.assert_allclose(run.output("sum.npz"), 5.0)
    assert list(run.results) == ["src", "a", "b", "sum"]  # topological order, whatever order they ended in


def test_one_job_runs_them_one_after_another(write, registry, cache):
    """The same graph with one job: the first branch waits for the second, which cannot start: the meeting
    node fails (what makes the test above mean something)."""
    with pytest.raises(NodeFailed) as ei:
        run_graph(load_graph(write("p.yaml", meeting(timeout=0.3)), registry=registry), cache=cache, jobs=1)
    assert ei.value.node == "a" and "did not start within" in ei.value.format()


def test_jobs_change_neither_results_nor_keys_nor_warnings(write, registry, tmp_path):
    from tbha_graph.core.cache import Cache

    chain = {j: run_graph(load_graph(write(f"c{j}.yaml", CHAIN), registry=registry), cache=Cache(tmp_path / f"c{j}"), jobs=j)
             for j in (1, 2)}
    assert {k: (r.key, r.fingerprints) for k, r in chain[1].results.items()} == \
           {k: (r.key, r.fingerprints) for k, r in chain[2].results.items()}
    assert list(chain[2].results) == list(chain[1].results)
    np.testing.assert_array_equal(chain[2].output("sum.npz"), chain[1].output("sum.npz"))
    # 'a' ends after 'b', yet its warning comes first: warnings follow the pipeline's order, not the clock's
    text = meeting(warn_a="first branch's warning", warn_b="second branch's warning").replace("factor: 2", "factor: 2, after: 0.3")
    run = run_graph(load_graph(write("m.yaml", text), registry=registry), cache=Cache(tmp_path / "m"), jobs=2)
    assert run.results["a"].seconds > run.results["b"].seconds
    expected = [{"node": "a", "message": "first branch's warning"}, {"node": "b", "message": "second branch's warning"}]
    assert run.node_warnings() == expected
    again = run_graph(load_graph(write("m.yaml", text), registry=registry), cache=Cache(tmp_path / "m"), jobs=2)
    assert {r.status for r in again.results.values()} == {"cached"} and again.node_warnings() == expected


def test_a_failing_node_is_named_and_nothing_after_it_runs(write, registry, cache, tmp_path):
    p = write("p.yaml", """
        nodes:
          src: {type: test.source}
          s: {type: test.scale, inputs: {x: src.x}}
          t: {type: test.scale, inputs: {x: src.x}, params: {factor: 3}}
          f: {type: test.fail, inputs: {x: s.y}}
          after: {type: test.add, inputs: {a: f.y, b: t.y}}
        outputs: {after.npz: after.y, t.npz: t.y}
    """)
    out = tmp_path / "out"
    with pytest.raises(NodeFailed) as ei:
        run_graph(load_graph(p, registry=registry), out_dir=out, cache=cache, jobs=2)
    assert ei.value.node == "f" and "frame 3" in ei.value.format()
    assert not out.exists()
    r = run_graph(load_graph(p, registry=registry), outputs=["t.npz"], cache=cache, jobs=2)
    assert {k: v.status for k, v in r.results.items()} == {"src": "cached", "t": "cached"}


def test_a_corrupt_cached_input_is_recomputed_with_two_jobs(write, registry, cache, tmp_path):
    p = write("p.yaml", CHAIN)
    r1 = run_graph(load_graph(p, registry=registry), cache=cache, jobs=2)
    (Path(r1.results["double"].entry_path) / "y.npz").write_bytes(b"garbage")  # bit rot in an input of 'sum'
    (Path(r1.results["sum"].entry_path) / "y.npz").write_bytes(b"garbage")  # and in an output that is written
    r2 = run_graph(load_graph(p, registry=registry, sets={"triple.factor": 4}), out_dir=tmp_path / "o", cache=cache, jobs=2)
    assert r2.results["double"].status == "ran" and r2.results["sum"].status == "ran"
    np.testing.assert_allclose(r2.output("sum.npz"), 2 * 2 + 2 * 4)
    with np.load(tmp_path / "o" / "sum.npz", allow_pickle=False) as z:
        np.testing.assert_allclose(z["value"], 12.0)


def test_a_pipeline_file_says_how_many_jobs(write, registry, cache):
    """``jobs: 2`` at the top of a pipeline file is its default (the meeting passes without jobs= in the call);
    jobs= in the call (tbha-run --jobs) overrides it; a bad value is an error naming the file and line."""
    from tbha_graph.core.errors import PipelineErrors

    text = "jobs: 2\n" + meeting(timeout=0.3).replace("\n        ", "\n").strip() + "\n"
    graph = load_graph(write("p.yaml", text), registry=registry)
    assert graph.jobs == 2
    np.testing.assert_allclose(run_graph(graph, cache=cache).output("sum.npz"), 5.0)
    with pytest.raises(NodeFailed):
        run_graph(load_graph(write("q.yaml", text.replace(uuid_of(text), uuid.uuid4().hex)), registry=registry),
                  cache=cache, jobs=1)
    with pytest.raises(PipelineErrors) as ei:
        load_graph(write("bad.yaml", text.replace("jobs: 2", "jobs: 0")), registry=registry)
    assert "bad.yaml:1" in str(ei.value) and "'jobs' must be a whole number" in str(ei.value)


def uuid_of(text: str) -> str:
    """The meeting group's name in a pipeline text made by :func:`meeting`."""
    return text.split('group: "', 1)[1].split('"', 1)[0]


def test_a_study_passes_jobs_on_and_dask_refuses_them(write, registry, cache, tmp_path):
    """``tbha-graph study --jobs`` reaches each run (the meeting passes only with 2); the dask executor, whose
    workers are its parallelism, refuses a jobs above 1 with a clear error."""
    from tbha_graph.core.errors import TbhaError
    from tbha_graph.core.study import run_study

    pipe = write("p.yaml", meeting(timeout=1.0))
    study = write("s.yaml", f"""
        base: {pipe}
        variants: {{only: {{}}}}
    """)
    rows = run_study(study, tmp_path / "study", cache=cache, registry=registry, jobs=2)
    assert [r["status"] for r in rows] == ["ok"]
    with pytest.raises(TbhaError, match="local executor"):
        run_graph(load_graph(pipe, registry=registry), cache=cache, executor="dask", jobs=2)


def test_ctrl_c_stops_a_running_node_at_its_next_step(write, registry, cache, tmp_path):
    """Ctrl-C while a node runs in a worker thread: the node stops at its next ctx.progress step (a thread cannot
    be interrupted; without the cancel event the run waited for the node's end, here 2,000 steps, 40 s) and the
    run raises KeyboardInterrupt (tbha-run: "interrupted ..., exit 130"), nothing of the node cached (its input's
    entry alone). The interrupt goes to the main thread, as a terminal's Ctrl-C does, half a second in, with
    Python's default handler in place whatever the process inherited; the node is long enough (40 s) that a slow
    machine still interrupts it."""
    import json
    import signal
    import threading

    log = tmp_path / "steps.log"
    text = f"""
        nodes:
          src: {{type: test.source, params: {{n: 3, value: 1.0}}}}
          slow: {{type: test.steps, inputs: {{x: src.x}}, params: {{log: "{log}", steps: 2000, sleep: 0.02}}}}
        outputs: {{y.npz: slow.y}}
    """
    graph = load_graph(write("p.yaml", text), registry=registry)
    # Python's own Ctrl-C handler for the test's length: a process started in the background by a shell without job
    # control (`cmd &` in a script) inherits SIGINT ignored, Python then installs none, and this test failed
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, signal.pthread_kill, (threading.main_thread().ident, signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_graph(graph, cache=cache, jobs=2)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    done = len(log.read_text().splitlines())
    assert 0 < done < 2000, done
    cached = [json.loads((d / "meta.json").read_text())["node_id"] for d in cache.iter_entries()]
    assert cached == ["src"], cached  # the interrupted node left nothing in the cache
