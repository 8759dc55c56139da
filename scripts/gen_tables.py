#!/usr/bin/env python3
"""Generate the colour and metal data tables of the Rust core.

Run from the repository root with the project venv (colour-science, numpy,
mitsuba 3.9.1):

    .venv/bin/python scripts/gen_tables.py

Writes
  rust-core/src/spectrum/cie_tables.rs  CIE 1931 2-degree CMFs and CIE D65 at 1 nm,
                                    360..830 nm.
  rust-core/src/optics/metals.rs        complex refractive indices (eta, k) of
                                    Al, Ag, Au, Cu, Cr from Mitsuba's data files,
                                    350..850 nm.

Sources and choices
-------------------
* CMFs: colour.MSDS_CMFS['CIE 1931 2 Degree Standard Observer'] (CIE 018:2019
  / CIE 015:2018 1 nm table), 360..830 nm, taken as is.
* D65: colour's tabulated CIE D65 (colour.SDS_ILLUMINANTS['D65'], CIE 015:2004
  Table T.1, 5 nm) stops at 780 nm; the CIE table runs to 830 nm. For
  785..830 nm we take the CIE decimals that Mitsuba 3 ships verbatim as float
  literals in include/mitsuba/core/spectrum.h (d65_table, 360..830 nm at 5 nm),
  parsed from the header text, so no float32 rounding enters. Cross-checks
  (printed, asserted):
    - colour's table and Mitsuba's literals are identical on 360..780 nm;
    - the CIE D-series reconstruction that colour implements
      (sd_CIE_illuminant_D_series: S0 + M1 S1 + M2 S2, M1 and M2 rounded to 3
      decimals, at the chromaticity of CCT 6500 * 1.4388 / 1.4380) matches both
      to < 1e-3 absolute (D65(560) = 100), including 785..830 nm, where it
      differs from the CIE literals by at most ~1e-4 (rounding: e.g. 825 nm
      gives 58.87655 vs the CIE's 58.8765).
  The 5 nm table is then linearly interpolated to 1 nm, as CIE 015 recommends
  for D65.
* Mitsuba's D65 as used in rendering (mi.cie_d65) is that same table stored as
  float32, linearly interpolated, and scaled by MI_CIE_D65_NORMALIZATION =
  1 / 98.99741751876255 (so that its luminance Y is 1). Up to that constant
  factor it differs from ours only by float32 rounding (the script prints the
  largest relative difference, ~1e-6). We keep the CIE scale
  (D65(560 nm) = 100); the Rust side normalises the weights itself, so the
  scale is irrelevant.
* Metals: mitsuba/data/ior/{Al,Ag,Au,Cu,Cr}.{eta,k}.spd (luxpop.com database;
  Cr is "Cr_llnl_cxro + Cr_palik"). The header says "Lambda (A)" but the
  values (about 298..886) are nanometres: Mitsuba's spectrum_from_file and its
  conductor plugin read them as nm, and as Angstrom they would be far UV. The
  tables are restricted to 350..850 nm: the interior samples are kept and the
  end points 350 and 850 nm are added by linear interpolation between the
  bracketing samples (so the piecewise-linear function on 350..850 is exactly
  Mitsuba's). If a file did not cover an end point, the end value would be
  clamped; the script reports it (none of the five files needs it).

Numbers are printed with Python's repr (shortest string that round-trips the
f64), so the Rust tables hold exactly the values computed here.
"""

import os
import re
import sys

import numpy as np
import colour
from colour.colorimetry import sd_CIE_illuminant_D_series
from colour.colorimetry.datasets.cmfs import DATA_CMFS_STANDARD_OBSERVER
from colour.temperature import CCT_to_xy_CIE_D

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC_DIR = os.path.join(ROOT, "rust-core", "src")
MITSUBA_IOR = os.path.join(
    os.path.dirname(sys.executable), "..", "lib", "python3.11", "site-packages",
    "mitsuba", "data", "ior",
)

LAMBDA_MIN, LAMBDA_MAX = 360, 830
LAMBDAS = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1, dtype=float)


def fmt(x):
    """Shortest round-trip decimal of an f64, always with a '.' or exponent."""
    s = repr(float(x))
    if "e" not in s and "." not in s and "inf" not in s and "nan" not in s:
        s += ".0"
    return s


def rust_array(values, per_line=6, indent="    "):
    items = [fmt(v) for v in values]
    lines = []
    for i in range(0, len(items), per_line):
        lines.append(indent + ", ".join(items[i:i + per_line]) + ",")
    return "\n".join(lines)


def rust_array3(rows, indent="    "):
    return "\n".join(
        indent + "[" + ", ".join(fmt(v) for v in row) + "]," for row in rows
    )


# --------------------------------------------------------------------------
# CMFs
# The raw dataset behind colour.MSDS_CMFS[...]: evaluating the MSDS object at
# integer wavelengths goes through its interpolator and adds float noise
# (0.00012989999999999996 for 0.0001299), so read the tabulated values.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
cmfs_raw = DATA_CMFS_STANDARD_OBSERVER[CMFS_NAME]
xyz = np.array([cmfs_raw[int(l)] for l in LAMBDAS], dtype=float)
cmfs = colour.MSDS_CMFS[CMFS_NAME]
assert np.max(np.abs(np.array([cmfs[float(l)] for l in LAMBDAS]) - xyz)) < 1e-12
assert xyz.shape == (LAMBDAS.size, 3)
assert np.all(np.isfinite(xyz))

# --------------------------------------------------------------------------
# D65 at 5 nm, 360..830
lam5 = np.arange(LAMBDA_MIN, LAMBDA_MAX + 1, 5, dtype=float)
d65_tab = colour.SDS_ILLUMINANTS["D65"]
tab_max = float(d65_tab.wavelengths[-1])

# Mitsuba's literal CIE table (include/mitsuba/core/spectrum.h, d65_table,
# 360..830 nm at 5 nm, the CIE decimals written as float literals).
MITSUBA_SPECTRUM_H = os.path.join(MITSUBA_IOR, "..", "..", "include", "mitsuba",
                                  "core", "spectrum.h")
with open(MITSUBA_SPECTRUM_H) as f:
    body = re.search(r"d65_table\[MI_CIE_SAMPLES\]\s*=\s*\{([^}]*)\}", f.read()).group(1)
mi_d65_5 = np.array([float(t.strip().rstrip("f")) for t in body.split(",") if t.strip()])
assert mi_d65_5.size == lam5.size, mi_d65_5.size

# CIE D-series reconstruction (S0 + M1 S1 + M2 S2, M1 and M2 rounded).
xy_d65 = CCT_to_xy_CIE_D(6500 * 1.4388 / 1.4380)
d65_rec = sd_CIE_illuminant_D_series(xy_d65, M1_M2_rounding=True)
rec_5 = np.array([float(d65_rec[l]) for l in lam5])

in_tab = lam5 <= tab_max
colour_5 = np.array([float(d65_tab[l]) for l in lam5[in_tab]])
d65_5 = np.concatenate([colour_5, mi_d65_5[~in_tab]])
diff_mi = np.max(np.abs(colour_5 - mi_d65_5[in_tab]))
diff_rec_tab = np.max(np.abs(colour_5 - rec_5[in_tab]))
diff_rec_ext = np.max(np.abs(mi_d65_5[~in_tab] - rec_5[~in_tab]))
print(f"D65: colour's table covers {d65_tab.wavelengths[0]}..{tab_max} nm")
print(f"  colour vs Mitsuba literal table, 360..{tab_max:.0f}: max |diff| = {diff_mi:.3g}")
print(f"  colour vs D-series reconstruction, 360..{tab_max:.0f}: max |diff| = {diff_rec_tab:.3g}")
print(f"  Mitsuba literal vs D-series reconstruction, {tab_max + 5:.0f}..830: "
      f"max |diff| = {diff_rec_ext:.3g}")
print("  785..830 nm values used:", ", ".join(
    f"{l:.0f}: {v}" for l, v in zip(lam5[~in_tab], d65_5[~in_tab])))
assert diff_mi < 1e-4 and diff_rec_tab < 1e-3 and diff_rec_ext < 1e-3
d65_1 = np.interp(LAMBDAS, lam5, d65_5)

try:
    import mitsuba as mi

    mi.set_variant("scalar_spectral")
    mi_d65 = np.array([float(mi.cie_d65(float(l))) for l in LAMBDAS])
    scale = d65_1[LAMBDAS == 560.0][0] / mi_d65[LAMBDAS == 560.0][0]
    rel = np.max(np.abs(mi_d65 * scale - d65_1) / d65_1)
    print(f"  Mitsuba cie_d65(lambda) * {scale:.9g} vs this D65 at 1 nm: "
          f"max relative diff = {rel:.3g} (float32 evaluation)")
    assert rel < 1e-5, rel
except ImportError:
    print("  mitsuba not importable: skipped the comparison with mi.cie_d65")

# --------------------------------------------------------------------------
# Write cie_tables.rs
n = LAMBDAS.size
cie_rs = f"""//! GENERATED by scripts/gen_tables.py: do not edit by hand.
//!
//! CIE 1931 2-degree colour-matching functions (x-bar, y-bar, z-bar) and the
//! CIE standard illuminant D65 (relative spectral power, D65(560 nm) = 100),
//! both at 1 nm steps from 360 to 830 nm inclusive ({n} samples), in f64.
//! Sources: colour-science {colour.__version__}, MSDS_CMFS["CIE 1931 2 Degree
//! Standard Observer"] (1 nm) and the CIE 5 nm D65 table (colour's tabulated
//! values to 780 nm, CIE D-series reconstruction for 785..830 nm), linearly
//! interpolated to 1 nm as CIE 015 recommends. Wavelengths in nanometres.

/// First wavelength of the tables (nm).
pub const TABLE_LAMBDA_MIN_NM: f64 = {fmt(LAMBDA_MIN)};
/// Number of 1 nm samples (360..=830 nm).
pub const TABLE_LEN: usize = {n};

/// CIE 1931 2-degree [x-bar, y-bar, z-bar] at 360, 361, ..., 830 nm.
#[rustfmt::skip]
pub const CIE1931_XYZ: [[f64; 3]; TABLE_LEN] = [
{rust_array3(xyz)}
];

/// CIE D65 relative spectral power at 360, 361, ..., 830 nm.
#[rustfmt::skip]
pub const D65: [f64; TABLE_LEN] = [
{rust_array(d65_1)}
];
"""

# --------------------------------------------------------------------------
# Metals
METALS = [("aluminium", "Al"), ("silver", "Ag"), ("gold", "Au"),
          ("copper", "Cu"), ("chromium", "Cr")]
M_MIN, M_MAX = 350.0, 850.0


def read_spd(path):
    lam, val = [], []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            a, b = line.split()[:2]
            lam.append(float(a))
            val.append(float(b))
    lam, val = np.array(lam), np.array(val)
    assert np.all(np.diff(lam) > 0), path
    # Units: nm despite the "Lambda (A)" header (see the module docstring).
    assert 250 < lam[0] < 400 and 800 < lam[-1] < 1000, (path, lam[0], lam[-1])
    return lam, val


def restrict(lam, val, name, what):
    inner = (lam > M_MIN) & (lam < M_MAX)
    lo = float(np.interp(M_MIN, lam, val))  # np.interp clamps outside
    hi = float(np.interp(M_MAX, lam, val))
    if lam[0] > M_MIN:
        print(f"  {name} {what}: starts at {lam[0]} nm > {M_MIN}: clamped")
    if lam[-1] < M_MAX:
        print(f"  {name} {what}: ends at {lam[-1]} nm < {M_MAX}: clamped")
    return (np.concatenate([[M_MIN], lam[inner], [M_MAX]]),
            np.concatenate([[lo], val[inner], [hi]]))


metal_blocks = []
metal_entries = []
for name, sym in METALS:
    le, eta = read_spd(os.path.join(MITSUBA_IOR, f"{sym}.eta.spd"))
    lk, k = read_spd(os.path.join(MITSUBA_IOR, f"{sym}.k.spd"))
    assert np.array_equal(le, lk), sym
    lam_r, eta_r = restrict(le, eta, name, "eta")
    _, k_r = restrict(lk, k, name, "k")
    up = sym.upper()
    print(f"{name}: {lam_r.size} samples, {lam_r[0]}..{lam_r[-1]} nm")
    metal_blocks.append(f"""#[rustfmt::skip]
const {up}_LAMBDA_NM: [f64; {lam_r.size}] = [
{rust_array(lam_r)}
];
#[rustfmt::skip]
const {up}_ETA: [f64; {lam_r.size}] = [
{rust_array(eta_r)}
];
#[rustfmt::skip]
const {up}_K: [f64; {lam_r.size}] = [
{rust_array(k_r)}
];
""")
    metal_entries.append(f"""    MetalTable {{
        name: "{name}",
        lambda_nm: &{up}_LAMBDA_NM,
        eta: &{up}_ETA,
        k: &{up}_K,
    }},""")

metals_rs = f"""//! GENERATED by scripts/gen_tables.py: do not edit by hand.
//!
//! Complex refractive index n = eta + i k of five metals, from Mitsuba 3's
//! data files mitsuba/data/ior/{{Al,Ag,Au,Cu,Cr}}.{{eta,k}}.spd (luxpop.com
//! database; Cr = Cr_llnl_cxro + Cr_palik). Wavelengths in nanometres (the
//! files' header says Angstrom, but the values are nm, as Mitsuba reads them).
//! Restricted to 350..850 nm: interior samples as in the files, end points
//! added by linear interpolation of the bracketing samples (no clamping was
//! needed). Interpolate linearly in wavelength.

// Measured data, not approximations of constants (e.g. eta = 6.28).
#![allow(clippy::approx_constant)]

/// Tabulated optical constants of one metal (strictly increasing `lambda_nm`).
#[derive(Debug, Clone, Copy)]
pub struct MetalTable {{
    /// Lower-case English name ("aluminium", "silver", ...).
    pub name: &'static str,
    /// Wavelengths (nm), strictly increasing, from 350 to 850.
    pub lambda_nm: &'static [f64],
    /// Real part of the refractive index at `lambda_nm`.
    pub eta: &'static [f64],
    /// Imaginary part (extinction coefficient) at `lambda_nm`.
    pub k: &'static [f64],
}}

/// Aluminium, silver, gold, copper and chromium, in this order.
pub const METALS: [MetalTable; 5] = [
{chr(10).join(metal_entries)}
];

{chr(10).join(metal_blocks)}"""

for fname, text in [("spectrum/cie_tables.rs", cie_rs), ("optics/metals.rs", metals_rs)]:
    path = os.path.join(SRC_DIR, fname)
    with open(path, "w") as f:
        f.write(text.rstrip("\n") + "\n")
    print("wrote", os.path.relpath(path, ROOT))
