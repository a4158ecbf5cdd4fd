"""Colour spaces and the color.* colour-model nodes."""
from __future__ import annotations

import numpy as np
import pytest

from tbha_graph.core.errors import NodeError
from tbha_graph.core.testing import run_node
from tbha_graph.mocap.color.hsv import hsv
from tbha_graph.mocap.color.lab import lab
from tbha_graph.mocap.bundles.colors import ColorModel, as_color_model
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity
from tbha_graph.mocap.color.spaces import SPACES, convert, rg_chromaticity as rg
from tbha_graph.mocap.segment.labels import PixelClassifier, class_mask
from tbha_graph.mocap.suit import load_suit

NODES = {"rg": rg_chromaticity, "hsv": hsv, "lab": lab}


def test_rg_values():
    px = np.array([[[0, 50, 200], [10, 10, 10], [0, 0, 0]]], np.uint8)  # BGR
    r, g, luma = rg(px)
    assert r[0, 0] == pytest.approx(0.8) and g[0, 0] == pytest.approx(0.2)
    assert r[0, 1] == pytest.approx(1 / 3) and g[0, 1] == pytest.approx(1 / 3)
    assert r[0, 2] == 0 and g[0, 2] == 0  # black: no division by zero
    assert luma[0, 0] == pytest.approx(250 / 3)


def test_rg_invariant_to_brightness_scaling():
    suit = load_suit()
    rng = np.random.default_rng(1)
    colours = np.vstack([np.stack([suit.rgb(c) for c in suit.colors]) * 255, rng.uniform(60, 255, (50, 3))])
    bright = np.clip(np.rint(colours), 0, 255).astype(np.uint8)[:, ::-1]  # BGR
    r0, g0, l0 = rg(bright)
    for k in (0.35, 0.6, 0.85):
        dim = np.rint(bright * k).astype(np.uint8)
        r1, g1, l1 = rg(dim)
        # only uint8 rounding of the dimmed pixel moves the chromaticity
        assert np.max(np.abs(r1 - r0)) < 0.012 and np.max(np.abs(g1 - g0)) < 0.012
        assert np.all(l1 < l0)  # while the luma follows the brightness
    # the HSV value channel is not invariant: the dimmed colours' luma differs, their chroma hardly
    c1, c2, v = convert("hsv", bright)
    d1, d2, dv = convert("hsv", np.rint(bright * 0.5).astype(np.uint8))
    assert np.all(dv < v) and np.max(np.hypot(d1 - c1, d2 - c2)) < 0.05


@pytest.mark.parametrize("space", SPACES)
def test_stack_conversion_matches_frame(space):
    rng = np.random.default_rng(2)
    stack = rng.integers(0, 256, (5, 12, 12, 3), dtype=np.uint8)
    whole = convert(space, stack)
    for i in range(5):
        one = convert(space, stack[i])
        for a, b in zip(whole, one):
            np.testing.assert_allclose(a[i], b, atol=1e-6)
    flat = convert(space, stack.reshape(-1, 3))
    np.testing.assert_allclose(flat[0], whole[0].reshape(-1), atol=1e-6)


@pytest.mark.parametrize("space", SPACES)
def test_color_model_classifies_suit_colours(space):
    model = run_node(NODES[space])["model"]
    assert isinstance(model, ColorModel) and model.space == space
    suit = load_suit()
    assert model.names[:-1] == list(suit.joints_by_colour()) and model.names[-1] == "head"
    assert model.classes[0].joints == suit.joints_by_colour()[model.names[0]]
    # colour regions never overlap
    cls = model.chroma_classes()
    for i, a in enumerate(cls):
        for b in cls[i + 1 :]:
            assert np.hypot(a.ref[0] - b.ref[0], a.ref[1] - b.ref[1]) > a.tol + b.tol
    clf = PixelClassifier(model)
    for k, c in enumerate(cls):
        rgb = suit.rgb(c.name) * 255
        # the patch colour, lit and shaded, is its own class (Lab's a*, b* shrink with the light)
        for shade in (1.0, 0.85) if space == "lab" else (1.0, 0.7, 0.45):
            px = np.full((1, 1, 3), np.rint(rgb[::-1] * shade), np.uint8)
            assert clf.labels(px)[0, 0] == k + 1, (c.name, shade)
    white = np.array([[[242, 242, 242], [150, 150, 150], [20, 22, 25]]], np.uint8)
    lab_ = clf.labels(white)
    assert lab_[0, 0] == 0 and lab_[0, 1] == 0  # suit (lit or shaded) is no patch
    assert lab_[0, 2] == len(model.classes)  # dark: the head class


@pytest.mark.parametrize("space", SPACES)
@pytest.mark.parametrize("shape", [(1, 1), (1, 4), (4, 1), (1, 3), (2, 2), (5, 7)])
def test_labels_and_masks_keep_the_image_shape(space, shape):
    """Any image size, 1x1 included, gives labels and masks of its own shape with the same values. OpenCV's
    array-with-Python-scalar operations change shape for tiny arrays between versions (5.1 returns a 1x1
    image times 3 as (4, 1), 5.0 refuses cv2.compare on it): the classifier must not depend on that."""
    clf = PixelClassifier(run_node(NODES[space])["model"])
    rng = np.random.default_rng(3)
    big = rng.integers(0, 256, (40, 40, 3), dtype=np.uint8)
    ref = clf.labels(big)
    img = np.ascontiguousarray(big[: shape[0], : shape[1]])
    lab_ = clf.labels(img)
    assert lab_.shape == shape and lab_.dtype == np.uint8
    np.testing.assert_array_equal(lab_, ref[: shape[0], : shape[1]])
    for c in range(len(clf.model.classes)):
        m = class_mask(lab_, c)
        assert m.shape == shape and m.dtype == np.uint8
        np.testing.assert_array_equal(m, np.where(lab_ == c + 1, 255, 0))


def test_model_round_trips_as_json():
    model = run_node(rg_chromaticity)["model"]
    again = as_color_model(model.model_dump(mode="json"))
    assert again == model
    with pytest.raises(NodeError, match="colour model"):
        as_color_model({"space": "rg"})


def test_suit_param_and_input(tmp_path):
    spec = load_suit().model_dump()
    spec["colors"]["red"] = "#e01010"
    path = tmp_path / "suit.yaml"
    import yaml

    path.write_text(yaml.safe_dump(spec))
    from_param = run_node(rg_chromaticity, {"suit": str(path)})["model"]
    from_input = run_node(rg_chromaticity, suit=load_suit(path))["model"]
    assert from_param == from_input
    default = run_node(rg_chromaticity)["model"]
    assert from_param.classes[0].ref != default.classes[0].ref


def test_indistinguishable_colours_are_refused():
    spec = load_suit().model_dump()
    spec["colors"]["orange"] = "#6b1414"  # a darker red: same chromaticity as red
    spec["colors"]["red"] = "#d62828"
    from tbha_graph.mocap.suit import SuitSpec

    with pytest.raises(NodeError, match="red and orange|orange and red"):
        run_node(rg_chromaticity, suit=SuitSpec.model_validate(spec))
