"""The mocap port types (tbha_graph.mocap.ports): one declaration each, real types checked before running,
values that survive the cache unchanged."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tbha_graph.cli.graph import main as graph_main
from tbha_graph.core.cache import Cache
from tbha_graph.core.errors import PortTypeError
from tbha_graph.core.registry import default_registry
from tbha_graph.core.runner import load_graph, run_graph
from tbha_graph.core.types import Arrays, Json
from tbha_graph.mocap import ports
from tbha_graph.mocap.body import Body, body_lengths
from tbha_graph.mocap.bundles.colors import ColorModel
from tbha_graph.mocap.skeleton import bone_lengths_array

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "pipelines" / "default.yaml"
SEED = ROOT / "pipelines" / "seed.yaml"


def _default_pipeline(tmp_path: Path, base: Path = DEFAULT, **rewire: str) -> Path:
    """A bundled pipeline (default.yaml) with absolute data paths, each ``old=new`` text replacement applied once."""
    text = base.read_text()
    text = text.replace("../data/sample/", str(ROOT / "data" / "sample") + "/")
    for old, new in rewire.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    p = tmp_path / "pipeline.yaml"
    p.write_text(text)
    return p


def test_validate_accepts_the_default_pipeline(tmp_path, capsys):
    assert graph_main(["validate", str(_default_pipeline(tmp_path))]) == 0
    assert ": ok (" in capsys.readouterr().out


def test_validate_rejects_colors_from_a_body_report(tmp_path, capsys):
    p = _default_pipeline(tmp_path, **{"inputs: {video: decode.video, colors: colors.model}":
                                       "inputs: {video: decode.video, colors: body.report}"})
    assert graph_main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"node 'segment': type mismatch: input 'colors' takes Model\[ColorModel\] but 'body\.report' gives Json", err), err


def test_validate_rejects_a_body_from_a_report_and_truth_as_motion(tmp_path, capsys):
    assert graph_main(["validate", str(_default_pipeline(tmp_path, SEED))]) == 0
    p = _default_pipeline(tmp_path, SEED, **{
        "inputs: {tracks: track.tracks, body: body.body}": "inputs: {tracks: track.tracks, body: body.report}",
        "inputs: {tracks: track.tracks, camera: calibrate.camera, body: body.body}":
            "inputs: {tracks: track.tracks, camera: calibrate.camera, body: body.report}",
        "inputs: {motion: fill.motion}": "inputs: {motion: truth.truth}"})
    assert graph_main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    for node in ("calibrate", "reconstruct"):
        assert f"node '{node}': type mismatch: input 'body' takes Model[Body] but 'body.report' gives Json" in err, err
    assert re.search(r"node 'smooth': type mismatch: input 'motion' takes motion\{.*\} but 'truth\.truth' gives truth", err), err


def test_bundles_are_nominal_among_themselves_structural_otherwise():
    assert not ports.MOTION.accepts(ports.TRUTH)          # two kinds of array bundle never mix
    assert not ports.SIDES.accepts(ports.ERRORS)
    assert ports.MOTION.accepts(ports.MOTION)
    assert ports.TRUTH.accepts(Arrays())                   # a generic bundle is checked when it runs
    assert Arrays().accepts(ports.MOTION)                  # and a generic input takes any bundle
    assert not ports.MOTION.accepts(Arrays({"points": ports.JOINTS2D}))
    assert not ports.COLORS.accepts(Json()) and not ports.BODY.accepts(Json())
    assert Json().accepts(ports.BODY)                      # a report-like input may still take a body


def test_every_mocap_node_declares_its_ports_from_ports_py():
    declared = {id(v) for v in vars(ports).values()}
    reg = default_registry()
    strays = []
    for spec in reg.specs():
        if not spec.module.startswith("tbha_graph.mocap."):
            continue
        for name, port in [*spec.inputs.items(), *spec.outputs.items()]:
            t = getattr(port, "type", port)
            # a report is free JSON described per node (ports.report_port); metrics.extra takes any report
            if id(t) not in declared and not (type(t) is Json and name in ("report", "extra")):
                strays.append(f"{spec.type}.{name}: {t.describe()}")
    assert not strays, strays


def test_body_checks_its_bones_and_reads_as_lengths():
    b = ports.BODY.validate({"left_knee": 0.43}, "body")
    assert isinstance(b, Body)
    want = bone_lengths_array({"left_knee": 0.43})
    assert np.array_equal(body_lengths(b), want) and np.array_equal(body_lengths({"left_knee": 0.43}), want)
    with pytest.raises(PortTypeError, match=r"(?s)body: not a valid Body: .*unknown bone 'left_kne' \(did you mean 'left_knee'\?\)"):
        ports.BODY.validate({"left_kne": 0.43}, "body")
    with pytest.raises(PortTypeError, match=r"bone 'chest' has length -0\.2"):
        ports.BODY.validate({"chest": -0.2}, "body")


def test_body_and_colors_round_trip_through_the_cache(tmp_path):
    """A body and a colour model stored by one run come back from the cache as the same typed values,
    with the same fingerprints (so downstream cache keys do not change)."""
    p = tmp_path / "p.yaml"
    p.write_text("nodes:\n"
                 "  body: {type: reconstruct.bone_lengths, params: {height: 1.62}}\n"
                 "  colors: {type: color.hsv}\n"
                 "outputs: {body.json: body.body, colors.json: colors.model}\n")
    cache = Cache(tmp_path / "cache")
    runs = [run_graph(load_graph(p), cache=cache, out_dir=tmp_path / f"out{i}") for i in range(2)]
    assert {r.status for r in runs[0].results.values()} == {"ran"}
    assert {r.status for r in runs[1].results.values()} == {"cached"}
    (b1, c1), (b2, c2) = [(r.output("body.json"), r.output("colors.json")) for r in runs]
    assert isinstance(b2, Body) and isinstance(c2, ColorModel)
    assert b2 == b1 and c2 == c1
    assert ports.BODY.fingerprint(b2) == ports.BODY.fingerprint(b1) == Json().fingerprint(b1.root)
    assert np.allclose(body_lengths(b2)[1:], bone_lengths_array()[1:] * body_lengths(b2)[1] / bone_lengths_array()[1])
