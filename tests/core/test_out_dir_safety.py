"""--out never deletes or overwrites what the project did not write (issue 14, item 1)."""
from __future__ import annotations

import json

import pytest
from testnodes import CHAIN

from tbha_graph.core.errors import TbhaError
from tbha_graph.core.runner import load_graph, run_graph


def _run(write, registry, cache, out, factor=2):
    p = write("chain.yaml", CHAIN.replace("factor: 2", f"factor: {factor}"))
    return run_graph(load_graph(p, registry=registry), out_dir=out, cache=cache)


def test_non_empty_folder_that_is_not_a_run_is_refused_and_kept(write, registry, cache, tmp_path):
    shoot = tmp_path / "shoot"
    (shoot / "sub").mkdir(parents=True)
    (shoot / "take1.mp4").write_bytes(b"my only copy")
    (shoot / "sub" / "notes.txt").write_text("keep")
    with pytest.raises(TbhaError, match="not empty.*not an earlier run"):
        _run(write, registry, cache, shoot)
    assert (shoot / "take1.mp4").read_bytes() == b"my only copy"
    assert (shoot / "sub" / "notes.txt").read_text() == "keep"
    assert sorted(p.name for p in shoot.iterdir()) == ["sub", "take1.mp4"]
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name or ".old-" in p.name]


def test_cli_refuses_the_issue_command_and_keeps_the_video(write, tmp_path, monkeypatch, capsys):
    from tbha_graph.cli.run import main

    shoot = tmp_path / "shoot"
    shoot.mkdir()
    (shoot / "take1.mp4").write_bytes(b"video")
    p = write("p.yaml", CHAIN)
    monkeypatch.setenv("TBHA_CACHE_DIR", str(tmp_path / "c"))
    assert main([str(p), "--plugin", "testnodes", "--out", str(shoot)]) == 2
    assert "refusing to write into" in capsys.readouterr().err
    assert (shoot / "take1.mp4").read_bytes() == b"video"


def test_empty_folder_is_used(write, registry, cache, tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    _run(write, registry, cache, out)
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "metrics.json", "sum.npz"]
    m = json.loads((out / "manifest.json").read_text())
    assert m["files"] == ["metrics.json", "sum.npz"]


def test_replacing_a_run_removes_only_its_own_files(write, registry, cache, tmp_path):
    out = tmp_path / "run"
    _run(write, registry, cache, out)
    (out / "my_notes.txt").write_text("mine")
    (out / "mine").mkdir()
    (out / "mine" / "clip.mp4").write_bytes(b"x")
    first = (out / "sum.npz").read_bytes()
    _run(write, registry, cache, out, factor=5)  # a different result replaces the old files
    assert (out / "sum.npz").read_bytes() != first
    assert (out / "my_notes.txt").read_text() == "mine"
    assert (out / "mine" / "clip.mp4").read_bytes() == b"x"
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "metrics.json", "mine", "my_notes.txt", "sum.npz"]


def test_replacing_a_run_drops_outputs_it_no_longer_writes_but_nothing_else(write, registry, cache, tmp_path):
    out = tmp_path / "run"
    _run(write, registry, cache, out)
    (out / "keep.txt").write_text("k")
    p = write("one.yaml", CHAIN.split("outputs:")[0] + "outputs:\n  sum.npz: sum.y\n")
    run_graph(load_graph(p, registry=registry), out_dir=out, cache=cache)
    assert sorted(x.name for x in out.iterdir()) == ["keep.txt", "manifest.json", "sum.npz"]


def test_a_run_folder_holding_a_user_file_named_like_a_new_output_is_refused(write, registry, cache, tmp_path):
    out = tmp_path / "run"
    p = write("one.yaml", CHAIN.split("outputs:")[0] + "outputs:\n  sum.npz: sum.y\n")
    run_graph(load_graph(p, registry=registry), out_dir=out, cache=cache)
    (out / "metrics.json").write_text("the user's own file")
    with pytest.raises(TbhaError, match="metrics.json would overwrite"):
        _run(write, registry, cache, out)
    assert (out / "metrics.json").read_text() == "the user's own file"


def test_a_forged_manifest_cannot_list_files_outside_the_run(write, registry, cache, tmp_path):
    outside = tmp_path / "precious.txt"
    outside.write_text("p")
    out = tmp_path / "run"
    _run(write, registry, cache, out)
    m = json.loads((out / "manifest.json").read_text())
    m["files"] += ["../precious.txt", str(outside)]
    (out / "manifest.json").write_text(json.dumps(m))
    _run(write, registry, cache, out, factor=3)
    assert outside.read_text() == "p"
