#!/usr/bin/env python3
"""make_heightmaps.py: write the synthetic height maps of scenes/heightmap.xml
(the `heightmap` surface of the diffraction BSDF) to scenes/heightmaps/:

  gaussian.npy  Gaussian-correlated random heights: rms 0.05 um, correlation
                C(r) = sigma^2 exp(-r^2/T^2) with T = 1.0 um
  fractal.npy   fractional Brownian surface, Hurst exponent 0.7: structure
                function D(r) = <(h(x+r)-h(x))^2> = s^2 (r/L)^(2H), s = 0.05 um
                at L = 1.0 um
  grating.npy   a sinusoidal grating along x: period 1.6 um, 0.12 um peak to
                peak, plus Gaussian-correlated noise (rms 0.005 um, T 0.5 um)
  scales.npy    a snake's scales: a hexagonal lattice (constant 1.2 um) of
                Gaussian bumps 0.08 um high (1/e radius 0.3 um), centres
                jittered by 0.03 um rms per coordinate, plus Gaussian-correlated
                noise (rms 0.003 um, T 0.3 um)

Each file is a float32 array of shape (ny, nx) (rows along y, columns along
x), heights in micrometres, pixel spacing 0.08 um (the scene's pixel_um) in
both directions. The maps are seeded: the same seed and size give the same
files. The gaussian and fractal maps are rescaled to their targets as
measured on the map itself (rms height; D at 1 um). One line per map with its
size and measured statistics is printed.

Run from the repository root (or `make heightmaps`):
  .venv/bin/python scripts/make_heightmaps.py [--size N] [--out DIR] [--seed S]
"""

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

PIXEL_UM = 0.08

GAUSSIAN_SIGMA_UM = 0.05
GAUSSIAN_T_UM = 1.0

FRACTAL_HURST = 0.7
FRACTAL_S_UM = 0.05
FRACTAL_LAG_UM = 1.0

GRATING_PERIOD_UM = 1.6
GRATING_PP_UM = 0.12
GRATING_NOISE_UM = 0.005
GRATING_NOISE_T_UM = 0.5

SCALES_LATTICE_UM = 1.2
SCALES_HEIGHT_UM = 0.08
SCALES_RADIUS_UM = 0.3
SCALES_JITTER_UM = 0.03
SCALES_NOISE_UM = 0.003
SCALES_NOISE_T_UM = 0.3

# Each map draws from its own stream of the seed, so that (say) the grating's
# noise is not the Gaussian map's noise scaled down.
_STREAM = {'gaussian': 1, 'fractal': 2, 'grating': 3, 'scales': 4}


def _rng(seed, name):
    return np.random.default_rng([seed, _STREAM[name]])


def _angular_frequencies(ny, nx, pixel_um):
    """|q| (rad/um) on the grid of np.fft.rfft2 of an (ny, nx) array."""
    qy = 2 * np.pi * np.fft.fftfreq(ny, pixel_um)[:, None]
    qx = 2 * np.pi * np.fft.rfftfreq(nx, pixel_um)[None, :]
    return np.hypot(qx, qy)


def gaussian_noise(shape, sigma_um, corr_um, rng, pixel_um=PIXEL_UM):
    """Gaussian-correlated heights, C(r) = sigma^2 exp(-r^2/T^2), by spectral
    synthesis: white noise filtered by the square root of the power spectrum
    pi T^2 sigma^2 exp(-|q|^2 T^2/4). The result is periodic on the map.
    Only the spectrum's shape matters: the sample is rescaled to exactly rms
    sigma after its mean is removed (the sample's own rms would scatter by
    about a percent at these sizes)."""
    ny, nx = shape
    q = _angular_frequencies(ny, nx, pixel_um)
    spectrum = np.fft.rfft2(rng.standard_normal(shape)) * np.exp(-(q * corr_um) ** 2 / 8)
    h = np.fft.irfft2(spectrum, s=shape)
    h -= h.mean()
    return h * (sigma_um / np.sqrt(np.mean(h ** 2)))


def gaussian_map(size=1024, seed=1, pixel_um=PIXEL_UM):
    rng = _rng(seed, 'gaussian')
    return gaussian_noise((size, size), GAUSSIAN_SIGMA_UM, GAUSSIAN_T_UM, rng,
                          pixel_um).astype(np.float32)


def _fast_len(n):
    """The smallest 2^a 3^b 5^c >= n (a size numpy's FFT handles quickly)."""
    best = 1 << int(np.ceil(np.log2(n)))
    p3 = 1
    while p3 < best:
        p35 = p3
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 5
        p3 *= 3
    return best


def fractal_map(size=1024, seed=1, pixel_um=PIXEL_UM, hurst=FRACTAL_HURST):
    """Fractional Brownian heights with D(r) = s^2 (r/L)^(2H).

    Plain periodic spectral synthesis (|q|^-(2+2H) on the map's own torus)
    lacks the wavelengths longer than the map, which for H = 0.7 carry most
    of the height differences at a few micrometres: on a 512 map the fitted
    2H between 0.3 and 3 um comes out 1.32 on average instead of 1.4. This
    is Stein's exact method instead (M. L. Stein, "Fast and exact simulation
    of fractional Brownian surfaces", J. Comput. Graph. Statist. 11, 2002),
    still an FFT synthesis: a stationary field whose covariance
    rho(r) = c0 - r^2H + c2 r^2 (r <= 1 in units u, 0 beyond; for 2H <= 1.5,
    c2 = H, c0 = 1 - H) is simulated exactly by circulant embedding on a
    torus of period 2u (its spectrum, the circulant's eigenvalues, is
    non-negative and falls as |q|^-(2+2H)); a random tilt of variance 2 c2
    |x|^2 restores the r^2 part, which makes h(x) - h(0) an fBm with
    D(r) = 2 (r/u)^2H exactly for |r| <= u. The map is the torus' corner of
    diagonal <= u: the torus is 2 sqrt(2) times the map across (2916^2 for a
    1024 map), and the map is not periodic. It keeps its overall tilt (0.025
    rad for the default seed at 1024): that is the fBm's own, and removing
    the best plane would take 10-20% off D at 1-3 um on a 512 map (fitted 2H
    1.33 again).

    The normalisation follows from that D, and the map is then rescaled to
    D(L) = s^2 as measured on it (a single 512 map's D at 1 um scatters by
    about 10% about the ensemble's; 200 maps averaged it within 1%)."""
    rng = _rng(seed, 'fractal')
    alpha = 2 * hurst
    if not 0 < alpha <= 1.5:
        raise ValueError('fractal_map: Stein\'s R = 1 embedding needs 0 < H <= 0.75')
    c2 = alpha / 2
    c0 = 1 - alpha / 2
    m = _fast_len(int(np.ceil(2 * np.sqrt(2) * (size - 1))) + 1)
    unit_um = m * pixel_um / 2          # the torus is two units across
    k = np.minimum(np.arange(m), m - np.arange(m)) * (pixel_um / unit_um)
    r = np.hypot(k[:, None], k[None, :])
    cov = np.where(r <= 1, c0 - r ** alpha + c2 * r ** 2, 0.0)
    eig = np.fft.rfft2(cov).real
    del cov, r
    # Stein's theorem makes the eigenvalues non-negative; what is left below
    # zero is rounding of a sum of m^2 terms.
    if eig.min() < -1e-9 * eig.max():
        raise RuntimeError('fractal_map: negative circulant eigenvalue %.3g' % eig.min())
    field = np.fft.irfft2(np.fft.rfft2(rng.standard_normal((m, m))) * np.sqrt(np.maximum(eig, 0)),
                          s=(m, m))[:size, :size]
    del eig
    y, x = np.mgrid[0:size, 0:size] * (pixel_um / unit_um)
    tilt = np.sqrt(2 * c2) * rng.standard_normal(2)
    h = field - field[0, 0] + tilt[0] * x + tilt[1] * y
    # D(r) = 2 (r/u)^2H in these units; s^2 (r/L)^2H in micrometres.
    h *= FRACTAL_S_UM / np.sqrt(2) * (unit_um / FRACTAL_LAG_UM) ** hurst
    h -= h.mean()
    h *= FRACTAL_S_UM / np.sqrt(structure_function(h, FRACTAL_LAG_UM, pixel_um))
    return h.astype(np.float32)


def grating_map(size=1024, seed=1, pixel_um=PIXEL_UM):
    rng = _rng(seed, 'grating')
    x = np.arange(size) * pixel_um
    sine = GRATING_PP_UM / 2 * np.sin(2 * np.pi * x / GRATING_PERIOD_UM)
    noise = gaussian_noise((size, size), GRATING_NOISE_UM, GRATING_NOISE_T_UM, rng, pixel_um)
    return (sine[None, :] + noise).astype(np.float32)


def scales_map(size=1024, seed=1, pixel_um=PIXEL_UM):
    """Gaussian bumps on a triangular lattice (one lattice vector along x),
    splatted one patch per bump. Bumps whose centres lie up to a patch's
    reach outside the map are included, so the edges carry their share."""
    rng = _rng(seed, 'scales')
    a = SCALES_LATTICE_UM
    r0 = SCALES_RADIUS_UM
    extent = size * pixel_um
    reach = 4 * r0                           # exp(-16): below 1e-7 of a bump
    row_um = a * np.sqrt(3) / 2
    j = np.arange(int(np.floor(-reach / row_um)), int(np.ceil((extent + reach) / row_um)) + 1)
    i = np.arange(int(np.floor(-reach / a)) - 1, int(np.ceil((extent + reach) / a)) + 1)
    cx = (i[None, :] + 0.5 * (j[:, None] % 2)) * a
    cy = np.broadcast_to(j[:, None] * row_um, cx.shape)
    cx, cy = cx.ravel(), cy.ravel()
    keep = (cx > -reach) & (cx < extent + reach) & (cy > -reach) & (cy < extent + reach)
    cx = cx[keep] + SCALES_JITTER_UM * rng.standard_normal(keep.sum())
    cy = cy[keep] + SCALES_JITTER_UM * rng.standard_normal(keep.sum())

    half = int(np.ceil(reach / pixel_um))
    offsets = np.arange(-half, half + 1)
    h = np.zeros(size * size)
    # The Gaussian is separable: each bump's patch is the outer product of
    # its row and column profiles. Chunks keep the patches' memory small.
    for s in range(0, len(cx), 2048):
        px = np.rint(cx[s:s + 2048] / pixel_um).astype(int)[:, None] + offsets
        py = np.rint(cy[s:s + 2048] / pixel_um).astype(int)[:, None] + offsets
        gx = np.exp(-((px * pixel_um - cx[s:s + 2048, None]) / r0) ** 2)
        gy = np.exp(-((py * pixel_um - cy[s:s + 2048, None]) / r0) ** 2)
        gx[(px < 0) | (px >= size)] = 0
        gy[(py < 0) | (py >= size)] = 0
        px = np.clip(px, 0, size - 1)
        py = np.clip(py, 0, size - 1)
        index = py[:, :, None] * size + px[:, None, :]
        h += np.bincount(index.ravel(), (gy[:, :, None] * gx[:, None, :]).ravel(),
                         minlength=size * size)
    h = SCALES_HEIGHT_UM * h.reshape(size, size)
    h += gaussian_noise((size, size), SCALES_NOISE_UM, SCALES_NOISE_T_UM, rng, pixel_um)
    return h.astype(np.float32)


MAPS = {'gaussian': gaussian_map, 'fractal': fractal_map, 'grating': grating_map,
        'scales': scales_map}


# ---------------------------------------------------------------------------
# Measurements on a map (what main prints)
# ---------------------------------------------------------------------------

def _lag_d(h, lag_px):
    """D at an integer lag, the mean of the x and y lags, from the map's own
    pairs (no wrap-around: not every map is periodic)."""
    h = np.asarray(h, dtype=np.float64)
    dx = np.mean((h[:, lag_px:] - h[:, :-lag_px]) ** 2)
    dy = np.mean((h[lag_px:, :] - h[:-lag_px, :]) ** 2)
    return 0.5 * (dx + dy)


def structure_function(h, r_um, pixel_um=PIXEL_UM):
    """D(r) (um^2) at r in micrometres: between the two integer lags around
    r, interpolated as a power law (exact for an fBm)."""
    lag = r_um / pixel_um
    lo = max(int(np.floor(lag)), 1)
    if lag == lo:
        return _lag_d(h, lo)
    d_lo, d_hi = _lag_d(h, lo), _lag_d(h, lo + 1)
    w = np.log(lag / lo) / np.log((lo + 1) / lo)
    return float(np.exp((1 - w) * np.log(d_lo) + w * np.log(d_hi)))


def fitted_2h(h, r_min_um=0.3, r_max_um=3.0, pixel_um=PIXEL_UM):
    """The slope of log D against log r between r_min and r_max."""
    lags = np.unique(np.rint(np.geomspace(r_min_um, r_max_um, 16) / pixel_um).astype(int))
    d = [_lag_d(h, int(k)) for k in lags]
    return float(np.polyfit(np.log(lags * pixel_um), np.log(d), 1)[0])


def correlation_length(h, pixel_um=PIXEL_UM):
    """The 1/e radius of the (circular) autocorrelation, averaged over
    directions in rings one pixel wide."""
    h = np.asarray(h, dtype=np.float64) - np.mean(h)
    acf = np.fft.irfft2(np.abs(np.fft.rfft2(h)) ** 2, s=h.shape)
    acf = np.fft.fftshift(acf / acf[0, 0])
    ny, nx = h.shape
    y, x = np.indices(h.shape)
    ring = np.rint(np.hypot(x - nx // 2, y - ny // 2)).astype(int)
    n = min(nx, ny) // 2
    profile = (np.bincount(ring.ravel(), acf.ravel())[:n] / np.bincount(ring.ravel())[:n])
    k = int(np.argmax(profile < np.exp(-1)))
    # Linear between the rings on either side of 1/e
    t = (profile[k - 1] - np.exp(-1)) / (profile[k - 1] - profile[k])
    return (k - 1 + t) * pixel_um


def _windowed_power(h):
    """|FFT|^2 of the map under a 2-D Hann window (no leakage from the edges
    of a non-periodic map), with the zero frequency centred."""
    h = np.asarray(h, dtype=np.float64) - np.mean(h)
    ny, nx = h.shape
    w = np.outer(np.hanning(ny), np.hanning(nx))
    return np.fft.fftshift(np.abs(np.fft.fft2(h * w)) ** 2)


def _parabolic(y_m, y_0, y_p):
    """Offset of a peak from three samples of its logarithm (exact for a
    Gaussian peak, a good fit to a Hann window's)."""
    a, b, c = np.log(y_m), np.log(y_0), np.log(y_p)
    return 0.5 * (a - c) / (a - 2 * b + c)


def grating_period(h, pixel_um=PIXEL_UM):
    """The period (um) of the strongest frequency along x, between bins."""
    h = np.asarray(h, dtype=np.float64)
    nx = h.shape[1]
    power = np.mean(np.abs(np.fft.rfft((h - h.mean(axis=1, keepdims=True)) * np.hanning(nx),
                                       axis=1)) ** 2, axis=0)
    k = int(np.argmax(power[1:-1])) + 1
    k_fine = k + _parabolic(power[k - 1], power[k], power[k + 1])
    return nx * pixel_um / k_fine


def lattice_constant(h, pixel_um=PIXEL_UM):
    """The triangular lattice constant (um) from the first ring of the FFT:
    its six strongest local maxima lie at |nu| = 2 / (sqrt(3) a)."""
    power = _windowed_power(h)
    ny, nx = power.shape
    inner = power[1:-1, 1:-1]
    peak = np.ones_like(inner, dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                peak &= inner > power[1 + dy:ny - 1 + dy, 1 + dx:nx - 1 + dx]
    py, px = np.nonzero(peak)
    py, px = py + 1, px + 1
    # The zero frequency (and the window's spread of it) is not a lattice peak.
    away = np.hypot(px - nx // 2, py - ny // 2) > 3
    py, px = py[away], px[away]
    top = np.argsort(power[py, px])[-6:]
    radii = []
    for y, x in zip(py[top], px[top]):
        fx = x + _parabolic(power[y, x - 1], power[y, x], power[y, x + 1]) - nx // 2
        fy = y + _parabolic(power[y - 1, x], power[y, x], power[y + 1, x]) - ny // 2
        radii.append(np.hypot(fx / (nx * pixel_um), fy / (ny * pixel_um)))
    return 2 / (np.sqrt(3) * np.mean(radii))


def describe(name, h, pixel_um=PIXEL_UM):
    """One line of statistics of a map."""
    rms = np.sqrt(np.mean((np.asarray(h, dtype=np.float64) - np.mean(h)) ** 2))
    line = '%-8s %dx%d, pixel_um %.3f, rms %.4f um, ' % (name, h.shape[1], h.shape[0],
                                                         pixel_um, rms)
    if name == 'gaussian':
        return line + 'correlation length (1/e) %.3f um (target %.2f)' % (
            correlation_length(h, pixel_um), GAUSSIAN_T_UM)
    if name == 'fractal':
        return line + ('D(1 um) %.5f um^2 (target %.5f), fitted 2H %.3f on 0.3-3 um '
                       '(target %.2f)') % (
            structure_function(h, FRACTAL_LAG_UM, pixel_um), FRACTAL_S_UM ** 2,
            fitted_2h(h, pixel_um=pixel_um), 2 * FRACTAL_HURST)
    if name == 'grating':
        return line + 'period from the FFT peak %.4f um (target %.2f)' % (
            grating_period(h, pixel_um), GRATING_PERIOD_UM)
    if name == 'scales':
        return line + 'lattice constant from the FFT\'s first ring %.4f um (target %.2f)' % (
            lattice_constant(h, pixel_um), SCALES_LATTICE_UM)
    raise KeyError(name)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--size', type=int, default=1024, help='pixels along x and y (default 1024)')
    ap.add_argument('--out', default=os.path.join(ROOT, 'scenes', 'heightmaps'),
                    help='output directory (default scenes/heightmaps)')
    ap.add_argument('--seed', type=int, default=1)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    maps = {}
    for name, make in MAPS.items():
        start = time.perf_counter()
        maps[name] = make(args.size, args.seed)
        seconds = time.perf_counter() - start
        print('%s (%.2f s)' % (describe(name, maps[name]), seconds))
    # Each file is written beside and renamed, gaussian.npy (make's target)
    # last: an interrupted run leaves no file that make would take for up to
    # date while another is missing or short.
    for name in sorted(maps, key=lambda n: n == 'gaussian'):
        path = os.path.join(args.out, name + '.npy')
        np.save(path + '.tmp.npy', maps[name])
        os.replace(path + '.tmp.npy', path)
    print('wrote %s/{%s}.npy' % (args.out, ','.join(maps)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
