"""Work folders under the temporary folder: nothing of a run is left there once the process has ended."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import pytest

from tbha_graph.core.errors import NodeFailed
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.core.scratch import pending, remove_at_exit, remove_pending, scratch_folder

HERE = Path(__file__).parent

TEXT = """
nodes:
  src: {type: test.source, params: {n: 2, value: 1.5}}
  t: {type: test.to_text, inputs: {x: src.x}}
outputs: {x.txt: t.text}
"""

FAILS = """
nodes:
  src: {type: test.source, params: {n: 2}}
  t: {type: test.to_text, inputs: {x: src.x}}
  f: {type: test.fail, inputs: {x: src.x}}
outputs: {x.txt: t.text, y.npz: f.y}
"""


def ours(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("tbha-"))


@pytest.fixture
def tmpdir_env(tmp_path, monkeypatch):
    """A private temporary folder for this process (tempfile's) and for its children ($TMPDIR)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.setenv("TMPDIR", str(tmp))
    return tmp


def test_a_run_without_a_cache_keeps_its_files_until_the_process_exits(write, tmpdir_env, tmp_path):
    """`tbha-run --no-cache` and `run_graph(cache=False)`: the returned values stay readable while the process
    lives (they are paths into the run's work folder); once it exits the folder is gone."""
    p = write("p.yaml", TEXT)
    script = textwrap.dedent(f'''
        import sys; sys.path.insert(0, {str(HERE)!r})
        import testnodes
        from pathlib import Path
        from tbha_graph.core.registry import Registry
        from tbha_graph.core.runner import load_graph, run_graph
        reg = Registry(); reg.add_module(testnodes, source="tests")
        g = load_graph({str(p)!r}, registry=reg)
        for out in (None, {str(tmp_path / "out")!r}):
            path = run_graph(g, out_dir=out, cache=False).output("x.txt")
            print(path, Path(path).read_text())
    ''')
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    lines = [line.split(" ", 1) for line in res.stdout.splitlines()]
    assert [text for _, text in lines] == ["1.5 1.5", "1.5 1.5"]  # readable before the exit
    assert all(Path(path).is_relative_to(tmpdir_env) for path, _ in lines)
    assert (tmp_path / "out" / "x.txt").read_text() == "1.5 1.5"  # the run directory is the user's: it stays
    assert ours(tmpdir_env) == []


def test_a_run_node_output_is_readable_until_the_process_exits(tmpdir_env):
    script = textwrap.dedent(f'''
        import sys; sys.path.insert(0, {str(HERE)!r})
        import numpy as np, testnodes
        from tbha_graph.core.testing import run_node
        print(run_node(testnodes.to_text, x=np.array([2.0, 3.0]))["text"].read_text())
    ''')
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "2 3"
    assert ours(tmpdir_env) == []


def test_a_failed_run_without_a_cache_removes_its_work_folder_at_once(write, registry, tmpdir_env):
    p = write("p.yaml", FAILS)
    with pytest.raises(NodeFailed):
        run_graph(load_graph(p, registry=registry), cache=False)
    assert ours(tmpdir_env) == []


def test_a_run_with_a_cache_removes_its_work_folder_at_once(write, registry, cache, tmpdir_env):
    p = write("p.yaml", TEXT)
    path = run_graph(load_graph(p, registry=registry), cache=cache).output("x.txt")
    assert Path(path).read_text() == "1.5 1.5" and Path(path).is_relative_to(cache.root)  # the cache holds it
    assert ours(tmpdir_env) == []


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_a_forked_child_leaves_its_parents_folders_alone(tmpdir_env):
    folder = scratch_folder("tbha-fork-")
    remove_at_exit(folder)
    try:
        pid = os.fork()
        if pid == 0:  # the child: what its exit would run
            remove_pending()
            os._exit(0)
        os.waitpid(pid, 0)
        assert folder.is_dir() and folder in pending()
    finally:
        remove_pending()
    assert not folder.exists() and folder not in pending()
