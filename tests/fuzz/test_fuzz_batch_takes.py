"""Fuzzing the take-list reader of ``tbha-graph batch`` (``tbha_graph.core.batch.collect_takes`` on a
YAML file). Property, per damaged file: a ``TbhaError`` naming the file, or takes equal to what a plain
``yaml.safe_load`` of the file lists (path resolved from the file's folder, name, ``set``) from a file
without duplicate keys; never another exception, never a hang.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from hypothesis import given

from fuzzlib import CASES, assert_names_file, case, fuzz_settings, mutated, time_limit, vocabulary
from tbha_graph.core.batch import collect_takes
from tbha_graph.core.yamlfile import load_yaml

BASE = b"""\
takes:
  - path: takes/monday_01.mp4
  - {name: tuesday, path: takes/t.mp4, set: {calibrate.focal_px: 900}}
  - takes/wednesday.mp4
"""


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz_takes")


def check_takes(raw: bytes, work: Path) -> None:
    path = work / "takes.yaml"
    path.write_bytes(raw)
    with time_limit(what="collect_takes"):
        try:
            takes = collect_takes(str(path))
        except Exception as e:  # noqa: BLE001
            errors = getattr(e, "errors", None) or [e]
            for err in errors:
                assert_names_file(err, path, need_line=False)
            return
    _, problems = load_yaml(path)
    assert not any("duplicate key" in p.message for p in problems), "a take list with duplicate keys was accepted"
    data = yaml.safe_load(raw)
    items = data["takes"] if isinstance(data, dict) else data
    assert len(takes) == len(items)
    for take, item in zip(takes, items):
        item = {"path": item} if isinstance(item, str) else item
        assert Path(take.path) == (work / str(item["path"])).resolve()
        if item.get("name"):
            assert take.name == str(item["name"])
        assert take.sets == dict(item.get("set") or {})


def test_intact_list_reads(work) -> None:
    check_takes(BASE, work)
    assert [t.name for t in collect_takes(str(work / "takes.yaml"))] == ["monday_01", "tuesday", "wednesday"]


FOUND = [
    case(BASE.replace(b"monday", b"mo\xe9nday"), "a byte that is not UTF-8"),
    case(BASE.replace(b"  - takes/wednesday.mp4", b"  - {path: a.mp4, path: b.mp4}"), "a duplicated key"),
    case(BASE.replace(b"set: {calibrate.focal_px: 900}", b"set: [900]"), "'set' that is not a mapping"),
]


@pytest.mark.parametrize("raw", FOUND, ids=lambda c: c.what[0])
def test_found_cases(raw, work) -> None:
    check_takes(raw, work)


@given(raw=mutated(BASE, vocabulary(BASE)))
@fuzz_settings(max_examples=100)
def test_fuzz_take_list(raw, work) -> None:
    CASES["batch take list"] += 1
    check_takes(raw, work)
