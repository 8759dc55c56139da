"""The synthetic height maps of scripts/make_heightmaps.py (the `heightmap`
surface's inputs, scenes/heightmaps/*.npy): each map has the statistics it
claims, measured here on 512 x 512 maps with this file's own estimators
(not the script's: the fractal map is rescaled by the script's own D(1 um)).

No Mitsuba, no plugin: numpy only, a few seconds.

Run: .venv/bin/python -m pytest tests/test_heightmaps_data.py
"""

import math
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import make_heightmaps as hm  # noqa: E402

SIZE = 512
SEED = 1
PIXEL_UM = 0.08        # the scene's pixel_um (scenes/heightmap.xml)
EXTENT_UM = SIZE * PIXEL_UM


@pytest.fixture(scope='module')
def maps():
    return {name: make(SIZE, SEED) for name, make in hm.MAPS.items()}


def structure(h, lag_px):
    """D at an integer lag: the mean of the x and y lags, pairs within the map."""
    h = h.astype(np.float64)
    return 0.5 * (np.mean((h[:, lag_px:] - h[:, :-lag_px]) ** 2)
                  + np.mean((h[lag_px:] - h[:-lag_px]) ** 2))


def test_main_writes_the_scenes_maps(tmp_path, capsys):
    """main() writes the four files scenes/heightmap.xml names, each the
    array its function makes, and prints a line for each."""
    assert hm.main(['--size', '128', '--seed', '3', '--out', str(tmp_path)]) == 0
    printed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    for name in ('gaussian', 'fractal', 'grating', 'scales'):
        written = np.load(tmp_path / (name + '.npy'))
        assert written.dtype == np.float32 and written.shape == (128, 128)
        assert np.array_equal(written, hm.MAPS[name](128, 3)), name
        assert name in printed, printed
    assert sorted(os.listdir(tmp_path)) == ['fractal.npy', 'gaussian.npy', 'grating.npy',
                                            'scales.npy']


@pytest.mark.parametrize('name', ['gaussian', 'fractal', 'grating', 'scales'])
def test_map_is_finite_float32_and_seeded(name, maps):
    h = maps[name]
    assert h.dtype == np.float32 and h.shape == (SIZE, SIZE)
    assert np.all(np.isfinite(h))
    assert np.std(h) > 0
    again = hm.MAPS[name](SIZE, SEED)
    assert np.array_equal(h, again), 'the same seed gave a different map'
    other = hm.MAPS[name](SIZE, SEED + 1)
    assert not np.array_equal(h, other), 'the seed is ignored'


def test_gaussian_rms_and_correlation(maps):
    """rms 0.05 um; the normalised autocorrelation at r = T = 1 um is exp(-1),
    averaged over a circle of radius T (the map is periodic: circular
    autocorrelation by FFT, bilinear between pixels)."""
    h = maps['gaussian'].astype(np.float64)
    h -= h.mean()
    rms = np.sqrt(np.mean(h ** 2))
    assert abs(rms / 0.05 - 1) < 0.02, rms
    acf = np.fft.irfft2(np.abs(np.fft.rfft2(h)) ** 2, s=h.shape)
    acf = np.fft.fftshift(acf / acf[0, 0])
    c = SIZE // 2
    angles = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    x = c + np.cos(angles) * 1.0 / PIXEL_UM
    y = c + np.sin(angles) * 1.0 / PIXEL_UM
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    ring = ((1 - fx) * (1 - fy) * acf[y0, x0] + fx * (1 - fy) * acf[y0, x0 + 1]
            + (1 - fx) * fy * acf[y0 + 1, x0] + fx * fy * acf[y0 + 1, x0 + 1])
    assert abs(ring.mean() - math.exp(-1)) < 0.05, ring.mean()


def test_fractal_structure_function(maps):
    """D(1 um) = s^2 = 0.0025 um^2 (between the lags of 12 and 13 pixels,
    linear in r), and log D against log r between 0.3 and 3 um has the
    slope 2H = 1.4 (a single 41 um map's slope scatters by about 0.06)."""
    h = maps['fractal']
    lag = 1.0 / PIXEL_UM
    lo = int(lag)
    d1 = structure(h, lo) + (lag - lo) * (structure(h, lo + 1) - structure(h, lo))
    assert abs(d1 / 0.0025 - 1) < 0.03, d1
    lags = np.arange(int(round(0.3 / PIXEL_UM)), int(round(3.0 / PIXEL_UM)) + 1)
    d = np.array([structure(h, k) for k in lags])
    # Log-spaced weights: every octave of lags counts alike
    two_h = np.polyfit(np.log(lags), np.log(d), 1, w=np.sqrt(1.0 / lags))[0]
    assert abs(two_h - 1.4) < 0.15, two_h


def test_grating_period_and_amplitude(maps):
    """The strongest frequency along x is 1/1.6 um^-1 (within a bin of
    1/41 um^-1), and the sine there is 0.12 um peak to peak (least squares
    on the column means, where the noise averages out)."""
    h = maps['grating'].astype(np.float64)
    profile = h.mean(axis=0)
    power = np.abs(np.fft.rfft(profile - profile.mean())) ** 2
    k = np.argmax(power[1:]) + 1
    assert abs(k - EXTENT_UM / 1.6) <= 1, (k, EXTENT_UM / 1.6)
    x = np.arange(SIZE) * PIXEL_UM
    basis = np.stack([np.sin(2 * np.pi * x / 1.6), np.cos(2 * np.pi * x / 1.6),
                      np.ones(SIZE)], axis=1)
    (a, b, _), *_ = np.linalg.lstsq(basis, profile, rcond=None)
    peak_to_peak = 2 * math.hypot(a, b)
    assert abs(peak_to_peak / 0.12 - 1) < 0.05, peak_to_peak


def test_scales_first_ring_is_hexagonal(maps):
    """The six strongest peaks of |FFT| (but the zero frequency's) are the
    triangular lattice's first ring: |nu| = 2 / (sqrt(3) a), a = 1.2 um,
    within 1.5 bins, at angles 60 degrees apart. Peaks are picked one by one,
    each clearing its neighbourhood (the map is not periodic: its edges
    leak into the bins beside each peak)."""
    h = maps['scales'].astype(np.float64)
    power = np.fft.fftshift(np.abs(np.fft.fft2(h - h.mean())) ** 2)
    c = SIZE // 2
    y, x = np.indices(power.shape)
    power[np.hypot(x - c, y - c) <= 3] = 0
    peaks = []
    for _ in range(6):
        py, px = np.unravel_index(np.argmax(power), power.shape)
        peaks.append((px - c, py - c))
        power[np.hypot(x - px, y - py) <= 4] = 0
    peaks = np.array(peaks, dtype=np.float64)
    ring_bins = 2 / (math.sqrt(3) * 1.2) * EXTENT_UM
    radii = np.hypot(peaks[:, 0], peaks[:, 1])
    assert np.all(np.abs(radii - ring_bins) < 1.5), (radii, ring_bins)
    angles = np.sort(np.degrees(np.arctan2(peaks[:, 1], peaks[:, 0])) % 360)
    steps = np.diff(np.append(angles, angles[0] + 360))
    assert np.all(np.abs(steps - 60) < 3), angles
