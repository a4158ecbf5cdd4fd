"""Issue 13: suits whose patches share colours (both kinds), and what the suit file may declare."""
from __future__ import annotations

from pathlib import Path

import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.mocap.suit import DEFAULT_SUIT_PATH, SEED_SUIT_PATH, load_suit


def test_both_bundled_suit_kinds_load():
    assert load_suit(DEFAULT_SUIT_PATH).sharing_kind == "upper_lower"
    seed = load_suit(SEED_SUIT_PATH)
    assert seed.sharing == "left_right" and seed.sharing_kind == "left_right"
    assert seed.joints_by_colour()["red"] == ["left_shoulder", "right_shoulder"]


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = SEED_SUIT_PATH.read_text()
    assert old in text
    p = tmp_path / "suit.yaml"
    p.write_text(text.replace(old, new))
    return p


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_unresolvable_sharing_names_file_and_line(tmp_path):
    # left_elbow and right_wrist in one colour: neither a mirror pair nor an upper/lower pair
    p = _edited(tmp_path, "right_wrist: magenta", "right_wrist: blue")
    p.write_text(p.read_text().replace("right_elbow: blue", "right_elbow: magenta"))
    with pytest.raises(NodeError) as e:
        load_suit(p)
    assert str(p) in str(e.value) and "left_elbow and right_wrist" in str(e.value)
    assert e.value.location.line == _line_of(p, "right_wrist:")


def test_three_patches_in_one_colour_refused(tmp_path):
    p = _edited(tmp_path, "chest: purple", "chest: orange")
    with pytest.raises(NodeError, match="3 patches") as e:
        load_suit(p)
    assert e.value.location.line == _line_of(p, "chest:")


def test_declared_kind_must_match(tmp_path):
    p = _edited(tmp_path, "sharing: left_right", "sharing: upper_lower")
    with pytest.raises(NodeError, match="left_right pair but the suit declares 'sharing: upper_lower'") as e:
        load_suit(p)
    assert e.value.location.line == _line_of(p, "right_shoulder:")
    p.write_text(p.read_text().replace("sharing: upper_lower", "sharing: mixed"))
    assert load_suit(p).sharing_kind == "left_right"
