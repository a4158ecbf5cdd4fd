"""Fuzzing the small YAML spec readers: the suit spec (``tbha_graph.mocap.suit.load_suit``, base:
``suit_default.yaml``) and the skeleton mapping (``tbha_graph.mocap.io.skeleton_map.load_mapping``,
base: the bundled ``cmu.yaml``).

Property, per mutated file: the reader raises a ``TbhaError`` (``NodeError``/``MappingError``) whose
message names the file, or it returns a spec equal to what a plain ``yaml.safe_load`` of the file
says, from a file without duplicate keys (PyYAML silently keeps the last of two equal keys: a
duplicated line with a changed value must be refused, not half-read); never another exception,
never a hang.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.core.yamlfile import load_yaml
from tbha_graph.mocap.io.skeleton_map import MAPPINGS_DIR, load_mapping
from tbha_graph.mocap.suit import DEFAULT_SUIT_PATH, load_suit

SUIT = DEFAULT_SUIT_PATH.read_bytes()
MAPPING = (MAPPINGS_DIR / "cmu.yaml").read_bytes()


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_specs")


def _has_duplicate_keys(path: Path) -> bool:
    _, problems = load_yaml(path)
    return any("duplicate key" in p.message for p in problems)


def check_suit_file(raw: bytes, work: Path) -> None:
    path = work / "suit.yaml"
    path.write_bytes(raw)
    with time_limit(what="load_suit"):
        try:
            suit = load_suit(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    assert not _has_duplicate_keys(path), "a suit file with duplicate keys was accepted"
    data = yaml.safe_load(raw)
    assert suit.colors == {str(k): str(v) for k, v in data["colors"].items()}
    assert suit.patches == {str(k): str(v) for k, v in data["patches"].items()}
    assert suit.patch_radius == float(data.get("patch_radius", 0.045))
    assert suit.patch_rgb().shape == (15, 3) and np.isfinite(suit.patch_rgb()).all()


def check_mapping_file(raw: bytes, work: Path) -> None:
    path = work / "mapping.yaml"
    path.write_bytes(raw)
    with time_limit(what="load_mapping"):
        try:
            m = load_mapping(path)
        except Exception as e:  # noqa: BLE001
            assert_names_file(e, path, need_line=False)
            return
    assert not _has_duplicate_keys(path), "a mapping file with duplicate keys was accepted"
    data = yaml.safe_load(raw)
    assert m.joints == {str(k): str(v) for k, v in data["joints"].items()}
    assert m.units_to_metres == float(data["units_to_metres"])
    assert m.axes == str(data.get("axes", "x y z"))


def test_unmutated_specs_load(work) -> None:
    check_suit_file(SUIT, work)
    check_mapping_file(MAPPING, work)


# cases the fuzzer found (kept as explicit examples)
FOUND_SUIT = [
    case(SUIT.replace(b"red: \"#d62728\"", b"red: \"#d6\xe92728\""), "a byte that is not UTF-8"),
    case(SUIT.replace(b"  left_hip: red\n", b"  left_hip: red\n  left_hip: blue\n"), "a duplicated key with another value"),
]
FOUND_MAPPING = [
    case(MAPPING.replace(b"joints:", b"joints:\xe9", 1), "a byte that is not UTF-8"),
]


@pytest.mark.parametrize("raw", FOUND_SUIT, ids=lambda c: c.what[0])
def test_found_suit_cases(raw, work) -> None:
    check_suit_file(raw, work)


@pytest.mark.parametrize("raw", FOUND_MAPPING, ids=lambda c: c.what[0])
def test_found_mapping_cases(raw, work) -> None:
    check_mapping_file(raw, work)


@given(raw=mutated(SUIT, vocabulary(SUIT)))
@fuzz_settings(max_examples=160)
def test_fuzz_suit_spec(raw, work) -> None:
    CASES["suit spec"] += 1
    check_suit_file(raw, work)


@given(raw=mutated(MAPPING, vocabulary(MAPPING)))
@fuzz_settings(max_examples=140)
def test_fuzz_skeleton_mapping(raw, work) -> None:
    CASES["skeleton mapping"] += 1
    check_mapping_file(raw, work)
