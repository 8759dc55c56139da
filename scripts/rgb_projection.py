#!/usr/bin/env python3
"""What bounding each RGB channel's white-furnace albedo would cost in colour.

The RGB path integrates a spectrum f against the linear sRGB weights W_c
(D65 x CIE 1931 -> sRGB, each integrating to 1; rust-core/src/spectrum) and
gamut-maps each evaluation, keeping its luminance (docs/parameters.md). The
weights have negative lobes, so the map adds light to the channel that a
narrow peak drives negative, and a grating's rainbow summed over the
hemisphere returns more than 1 in its largest channel (docs/energy.md).

A linear, non-negative projection would bound every channel by the spectral
albedo: RGB = integral f W'' with W'' >= 0 and integral W''_c = 1. This
prints, for two such W'' (each wavelength's colour gamut-mapped keeping
luminance, or clipped at 0, then renormalised), how far they move the colour
of smooth spectra (metals' Fresnel reflectance at normal incidence, tilted
spectra, broad bands) from today's exact projection, in 8-bit sRGB steps,
and the renormalisation each channel needs. Reads the generated tables in
rust-core/src (CIE 1931, D65, the metals' eta and k). numpy only.

    .venv/bin/python scripts/rgb_projection.py
"""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
XYZ_TO_SRGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
LAMBDA_NM = np.arange(360.0, 831.0)
# Trapezoid weights of the 1 nm grid (the core's reference rule).
TRAPEZOID = np.ones(LAMBDA_NM.size)
TRAPEZOID[0] = TRAPEZOID[-1] = 0.5


def rust_array(text, name):
    """The numbers of `const NAME: ... = [ ... ];` in generated Rust source."""
    start = text.index("= [", text.index("const " + name)) + 3
    body = text[start : text.index("];", start)]
    return np.array([float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", body)])


def luminance_keeping_map(rgb):
    """The core's gamut map (spectrum::gamut_map) on rows of RGB."""
    rgb = rgb.copy()
    low = rgb.min(axis=1)
    y = rgb @ LUMINANCE
    out = low < 0
    s = low[out] / (low[out] - y[out])
    rgb[out] += s[:, None] * (y[out][:, None] - rgb[out])
    return rgb


def integrate(f, weights):
    return ((TRAPEZOID * f)[:, None] * weights).sum(axis=0)


def to_8bit(linear):
    x = np.clip(linear, 0.0, None)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return 255.0 * encoded


def main():
    cie = (ROOT / "rust-core/src/spectrum/cie_tables.rs").read_text()
    xyz = rust_array(cie, "CIE1931_XYZ").reshape(-1, 3)
    d65 = rust_array(cie, "D65")
    weights = (xyz @ XYZ_TO_SRGB.T) * d65[:, None]
    weights /= integrate(np.ones(LAMBDA_NM.size), weights)

    options = {}
    for name, mapped in (
        ("luminance-keeping", luminance_keeping_map(weights)),
        ("clipped", np.clip(weights, 0.0, None)),
    ):
        norm = integrate(np.ones(LAMBDA_NM.size), mapped)
        options[name] = (mapped / norm, norm)
        print(f"W'' {name}: each channel's integral before renormalising "
              f"R {norm[0]:.3f} G {norm[1]:.3f} B {norm[2]:.3f}")

    metals = (ROOT / "rust-core/src/optics/metals.rs").read_text()

    def fresnel_normal(prefix):
        lam = rust_array(metals, prefix + "_LAMBDA_NM")
        n = np.interp(LAMBDA_NM, lam, rust_array(metals, prefix + "_ETA")) + 1j * np.interp(
            LAMBDA_NM, lam, rust_array(metals, prefix + "_K")
        )
        return np.abs((n - 1) / (n + 1)) ** 2

    spectra = {
        "flat (white)": np.ones(LAMBDA_NM.size),
        "gold, Fresnel at normal incidence": fresnel_normal("AU"),
        "copper, Fresnel at normal incidence": fresnel_normal("CU"),
        "aluminium, Fresnel at normal incidence": fresnel_normal("AL"),
        "0.3 (550/lambda)^4 (a blue halo)": 0.3 * (550.0 / LAMBDA_NM) ** 4,
        "0.3 (lambda/550)^2 (reddish)": 0.3 * (LAMBDA_NM / 550.0) ** 2,
        "band 500 nm, sd 40 nm": np.exp(-0.5 * ((LAMBDA_NM - 500.0) / 40.0) ** 2),
        "band 600 nm, sd 40 nm": np.exp(-0.5 * ((LAMBDA_NM - 600.0) / 40.0) ** 2),
    }
    print()
    print("| spectrum | today (exact, gamut-mapped) | luminance-keeping W'' | "
          "8-bit change | clipped W'' | 8-bit change |")
    print("|---|---|---|---|---|---|")
    for name, f in spectra.items():
        today = luminance_keeping_map(integrate(f, weights)[None])[0]
        cells = [name, np.array2string(today, precision=3)]
        for mapped, _ in options.values():
            rgb = integrate(f, mapped)
            change = np.abs(to_8bit(rgb) - to_8bit(today)).max()
            cells += [np.array2string(rgb, precision=3), f"{change:.0f}"]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
