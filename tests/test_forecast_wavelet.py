"""The per-window wavelet decomposition: exact reconstruction and causality."""

from __future__ import annotations

import numpy as np
import pytest
import pywt
from numpy.lib.stride_tricks import sliding_window_view

from opfbench.errors import InputError
from opfbench.forecasting.wavelet import WaveletComponent, component_names, decompose_windows


@pytest.mark.parametrize("width, wavelet", [(24, "db2"), (30, "db2"), (64, "db4"), (17, "haar")])
def test_components_reconstruct_each_window(width, wavelet):
    windows = np.random.default_rng(width).normal(size=(50, width)) * 3.0 + 1.0
    parts = decompose_windows(windows, wavelet, level=3)
    assert parts.shape == (4, 50, width)
    np.testing.assert_allclose(parts.sum(axis=0), windows, rtol=0, atol=1e-9)
    # every component carries signal (no band is silently empty)
    assert all(np.abs(p).max() > 1e-3 for p in parts)


def test_component_transform_matches_decomposition():
    windows = np.random.default_rng(1).normal(size=(7, 24))
    parts = decompose_windows(windows)
    assert component_names(3) == ("A3", "D3", "D2", "D1")
    for j in range(4):
        np.testing.assert_array_equal(WaveletComponent(j)(windows), parts[j])


def test_too_short_window_is_rejected():
    with pytest.raises(InputError, match="longer window"):
        decompose_windows(np.zeros((2, 16)), "db2", level=3)


def _per_window_features(series: np.ndarray, width: int) -> np.ndarray:
    """Features the models see for target t: components of the window series[t-width:t]."""
    windows = sliding_window_view(series[:-1], width)
    return decompose_windows(windows)[:, :, -1].T  # (targets, components)


def _whole_series_features(series: np.ndarray, width: int) -> np.ndarray:
    """The leaky variant: decompose the whole series once, then slice."""
    coeffs = pywt.wavedec(series, "db2", level=3)
    parts = [
        pywt.waverec([c if j == i else np.zeros_like(c) for j, c in enumerate(coeffs)], "db2")[: len(series)] for i in range(4)
    ]
    return np.stack([p[width - 1 : -1] for p in parts], axis=1)


def _depends_on_future(features_of, width: int = 24) -> bool:
    rng = np.random.default_rng(3)
    series = rng.normal(size=400)
    t = 250  # target index; the features for t may use series[:t] only
    base = features_of(series, width)
    changed = series.copy()
    changed[t:] = rng.normal(size=len(series) - t) * 10
    after = features_of(changed, width)
    row = t - width  # feature row of target t
    return not np.array_equal(base[: row + 1], after[: row + 1])


def test_per_window_features_do_not_see_the_future():
    assert not _depends_on_future(_per_window_features)


def test_the_causality_check_catches_a_whole_series_decomposition():
    assert _depends_on_future(_whole_series_features)
