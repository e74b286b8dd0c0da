"""Tests of iat.measure.metrics on synthetic images."""

import math

import numpy as np
import pytest

from iat.measure import metrics


def _rand(seed=0, shape=(24, 32, 3)):
    return np.random.default_rng(seed).random(shape)


def test_luminance_rec709():
    assert metrics.luminance([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    img = np.zeros((2, 3, 3))
    img[..., 1] = 2.0
    np.testing.assert_allclose(metrics.luminance(img), np.full((2, 3), 2 * 0.7152))
    with pytest.raises(ValueError):
        metrics.luminance(np.zeros((4, 4)))


def test_psnr_identical_is_inf():
    a = _rand()
    assert metrics.psnr(a, a.copy()) == math.inf


def test_psnr_known_mse():
    b = np.zeros((8, 8, 3))
    b[0, 0] = 2.0  # peak 2 by default
    a = b + 0.1  # MSE exactly 0.01
    assert metrics.psnr(a, b) == pytest.approx(10 * np.log10(4.0 / 0.01), abs=1e-9)
    assert metrics.psnr(a, b, peak=1.0) == pytest.approx(20.0, abs=1e-9)
    assert metrics.psnr(a, np.zeros_like(b)) == -math.inf  # zero peak


def test_psnr_rejects_mismatched_shapes():
    with pytest.raises(ValueError):
        metrics.psnr(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))


def test_srgb_tonemap():
    x = np.array([[[0.0, 0.5, 4.0]]])
    y = metrics.srgb_tonemap(x)
    assert y.dtype == np.float32
    assert y[0, 0, 0] == 0.0 and y[0, 0, 2] == pytest.approx(1.0)
    assert y[0, 0, 1] == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055, abs=1e-6)
    assert metrics.srgb_tonemap(x, exposure=0.25)[0, 0, 2] == pytest.approx(1.0)


def test_flip_identical_zero_and_different_positive():
    pytest.importorskip("flip_evaluator")
    a = _rand(1) * 0.8
    assert metrics.flip(a, a.copy()) == 0.0
    b = np.clip(a + 0.2 * _rand(2), 0, None)
    e = metrics.flip(b, a)
    assert 0.0 < e <= 1.0
    # a bigger change is a bigger error
    assert metrics.flip(a * 0.2, a) > metrics.flip(a * 0.9, a)
    mean, emap = metrics.flip(b, a, return_map=True)
    assert emap.shape == a.shape[:2] and mean == pytest.approx(e)


def test_flip_exposure_applies_before_clamp():
    pytest.importorskip("flip_evaluator")
    # both images saturate at exposure 1 (identical LDR), differ at a low exposure
    a = np.full((16, 16, 3), 4.0)
    b = np.full((16, 16, 3), 8.0)
    assert metrics.flip(b, a) == 0.0
    assert metrics.flip(b, a, exposure=0.1) > 0.0


def test_relative_error_known_value():
    ref = np.ones((4, 4, 3))
    test = ref * 1.1
    assert metrics.relative_error(test, ref) == pytest.approx(0.1)
    # floor: black reference pixel, test luminance 0.01 -> 0.01 / 1e-3 = 10
    ref2 = ref.copy()
    ref2[0, 0] = 0.0
    test2 = ref2.copy()
    test2[0, 0] = 0.01
    mean, emap = metrics.relative_error(test2, ref2, return_map=True)
    assert emap[0, 0] == pytest.approx(10.0)
    assert mean == pytest.approx(10.0 / 16)
    # a mask drops that pixel
    mask = np.ones((4, 4), bool)
    mask[0, 0] = False
    assert metrics.relative_error(test2, ref2, mask=mask) == pytest.approx(0.0, abs=1e-12)
    assert math.isnan(metrics.relative_error(test2, ref2, mask=np.zeros((4, 4), bool)))
    with pytest.raises(ValueError):
        metrics.relative_error(test2, ref2, mask=np.ones((3, 3), bool))


def test_lit_mask():
    img = np.zeros((10, 10, 3))
    img[:5] = 1.0  # lit half
    img[5:, :5] = 0.01  # dim: below 2 % of the 99th percentile (1.0)
    img[9, 9] = 1000.0  # one hot emitter pixel: 2 % of the max (20) would drop the lit half
    m = metrics.lit_mask(img)
    assert m.shape == (10, 10) and m.dtype == bool
    assert m[:5].all() and not m[5:, :5].any() and m[9, 9]
    assert not m[5:, 5:9].any()
    assert not metrics.lit_mask(np.zeros((4, 4, 3))).any()


def test_edge_mismatch():
    a = np.zeros((5, 3))
    b = np.zeros((5, 3))
    b[2, 1] = 0.3
    b[4, 0] = -0.15
    mx, mean = metrics.edge_mismatch(a, b)
    assert mx == pytest.approx(0.3)
    assert mean == pytest.approx(0.45 / 15)
    assert metrics.edge_mismatch(np.zeros((0, 3)), np.zeros((0, 3))) == (0.0, 0.0)
    with pytest.raises(ValueError):
        metrics.edge_mismatch(np.zeros((2, 3)), np.zeros((3, 3)))


def test_smooth_lit_mask_leaves_out_edges_and_dark_pixels():
    ref = np.zeros((16, 16, 3))
    ref[:, 4:] = 1.0  # a lit region with one vertical edge at column 4, columns 0-3 dark
    m = metrics.smooth_lit_mask(ref)
    assert not m[:, :5].any()  # dark, and the lit column next to the edge
    assert m[:, 6:].all()


def test_reference_errors_known_values():
    ref = np.full((16, 16, 3), 0.5)
    img = ref * 1.1  # 10 % too bright everywhere
    e = metrics.reference_errors(img, ref)
    assert e["rel_smooth"] == pytest.approx(0.1)
    assert e["rel_blocks"] == pytest.approx(0.1)
    assert e["bias"] == pytest.approx(0.1)
    with pytest.raises(ValueError):
        metrics.reference_errors(img[:8], ref)
