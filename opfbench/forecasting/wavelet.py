"""Causal wavelet decomposition of input windows (paper §II, 3-level DWT: A3, D3, D2, D1).

The decomposition is applied to each input window on its own — never to the whole
series, which would let every feature see the future. A window of `w` past values is
transformed with `pywt.wavedec`; each component is rebuilt to window length by
`pywt.waverec` with all other coefficient bands set to zero. The inverse DWT is
linear, so the components add up to the window exactly (up to rounding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pywt

from opfbench.errors import InputError


def component_names(level: int) -> tuple[str, ...]:
    """Names in pywt coefficient order: (A<level>, D<level>, ..., D1)."""
    return (f"A{level}", *(f"D{j}" for j in range(level, 0, -1)))


def check_level(window: int, wavelet: str, level: int) -> None:
    """Raise InputError when `window` is too short for a `level`-level DWT with `wavelet`."""
    if level < 1 or pywt.dwt_max_level(window, pywt.Wavelet(wavelet).dec_len) < level:
        raise InputError(
            f"a {level}-level {wavelet} DWT needs a longer window than {window} "
            f"(max level {pywt.dwt_max_level(window, pywt.Wavelet(wavelet).dec_len)})"
        )


def reconstruct_component(windows: np.ndarray, index: int, wavelet: str, level: int, mode: str) -> np.ndarray:
    """Component `index` (pywt order) of each row of `windows` (N, w), rebuilt to (N, w)."""
    width = windows.shape[-1]
    coeffs = pywt.wavedec(windows, wavelet, mode=mode, level=level, axis=-1)
    kept = [c if j == index else np.zeros_like(c) for j, c in enumerate(coeffs)]
    return pywt.waverec(kept, wavelet, mode=mode, axis=-1)[..., :width]


def decompose_windows(windows: np.ndarray, wavelet: str = "db2", level: int = 3, mode: str = "symmetric") -> np.ndarray:
    """All components of each window: (N, w) -> (level + 1, N, w), summing to `windows`."""
    data = np.atleast_2d(np.asarray(windows, dtype=float))
    check_level(data.shape[-1], wavelet, level)
    return np.stack([reconstruct_component(data, j, wavelet, level, mode) for j in range(level + 1)])


@dataclass(frozen=True)
class WaveletComponent:
    """Window transform: keep component `index` (0 = A<level>, 1 = D<level>, ..., level = D1)."""

    index: int
    wavelet: str = "db2"
    level: int = 3
    mode: str = "symmetric"

    @property
    def label(self) -> str:
        return component_names(self.level)[self.index]

    def __call__(self, windows: np.ndarray) -> np.ndarray:
        """(N, w) windows -> (N, w) reconstruction of this component, window by window."""
        return reconstruct_component(np.asarray(windows, dtype=float), self.index, self.wavelet, self.level, self.mode)
