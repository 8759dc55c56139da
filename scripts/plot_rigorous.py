#!/usr/bin/env python3
"""Rigorous (RCWA) against Kirchhoff per-order efficiencies for the compact disc
(issue 41; docs/rigorous_comparison.md).

The disc of the slides (rect aluminium bumps 0.15 um high, 0.5 um wide, period
2.5 um, coherence 50 um: the core's `"surface": "cd"` defaults), at 450, 550
and 650 nm, incidence 0-80 degrees in the plane across the grooves:

- rigorous: `core.rigorous_solve` (Li's rules), unpolarised = mean of s and p;
- Kirchhoff: the core's BRDF (`"energy": "stam"` and the default
  `"conserving"`) integrated over each order's lobe, int f cos_o d omega_o over
  the directions whose direction cosine across the grooves lies within half an
  order spacing of the order's (all of the other coordinate).

Writes docs/rigorous_orders.png and docs/rigorous_totals.png and prints the
validation of the integration, the solver's convergence and the tables (in
markdown). Run from the repository root:

    .venv/bin/python scripts/plot_rigorous.py

Takes about two minutes on two cores (`--step 5` for a quick look).

Conventions. Core BRDF: local frame, z the normal, the grooves along y (the
surface varies along x), wi and wo pointing away from the surface. The light
comes from wi = (-sin th, 0, cos th); the rigorous solver's order m leaves with
direction cosine kx_m = sin th + m lambda / period, i.e. wo_x = kx_m here.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))
from stam_diffraction import core  # noqa: E402

PERIOD, HEIGHT, WIDTH, COHERENCE = 2.5, 0.15, 0.5, 50.0
GEOMETRY = dict(period_um=PERIOD, profile="rect", height_um=HEIGHT, width_um=WIDTH,
                fresnel="aluminium")
WAVELENGTHS = (450.0, 550.0, 650.0)
TABLE_ANGLES = (0.0, 30.0, 60.0, 75.0)
MODES = ("stam", "conserving")
N_RIGOROUS = 80      # orders -N..N of the plotted and tabulated solves
N_COARSE = 40        # compared against N_RIGOROUS over the whole sweep
N_FINE = 160         # compared against N_RIGOROUS at the table's points
PLOT_ORDERS = (-2, -1, 0, 1, 2)
FINE_SIGMAS = 10.0   # fine quadrature within +- this many lobe widths


# -- quadrature ------------------------------------------------------------------

_GL5 = np.polynomial.legendre.leggauss(5)


def panels(a, b, count):
    """Gauss-Legendre (5 nodes) over count equal panels of [a, b] (arrays of
    endpoints allowed; a zero-width interval gets zero weights): nodes and
    weights with shape a.shape + (5 count,)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    t = np.linspace(0.0, 1.0, count + 1)
    lo = a[..., None] + (b - a)[..., None] * t[:-1]
    h = ((b - a) / count)[..., None]
    x = (lo[..., None] + h[..., None] * (_GL5[0] + 1) / 2).reshape(a.shape + (-1,))
    w = np.broadcast_to((h[..., None] * _GL5[1] / 2), lo.shape + (5,)).reshape(a.shape + (-1,))
    return x, w


def split_nodes(lo, hi, c, s):
    """Nodes over [lo, hi]: 10 panels over c +- FINE_SIGMAS s (clipped), 3 on each side."""
    a = np.clip(c - FINE_SIGMAS * s, lo, hi)
    b = np.clip(c + FINE_SIGMAS * s, lo, hi)
    parts = [panels(a, b, 10), panels(lo, a, 3), panels(b, hi, 3)]
    return (np.concatenate([p[0] for p in parts], -1), np.concatenate([p[1] for p in parts], -1))


def window_energy(brdf, wi, lam, lo, hi, c, s):
    """int f(wi, wo) cos_o d omega_o over wo_x in [lo, hi] (all wo_y), for a lobe
    centred at wo_x = c, wo_y = -wi_y = 0 of width s in direction cosines.

    Coordinates (x, phi): wo = (x, R sin phi, R cos phi), R = sqrt(1 - x^2), so
    that cos_o d omega = dx d(wo_y) = cos_o dx dphi: the integrand f cos_o stays
    finite at the horizon (f's 1/cos_o cancels)."""
    if hi <= lo:
        return 0.0
    x, wx = split_nodes(lo, hi, c, s)
    r = np.sqrt(np.clip(1.0 - x * x, 0.0, None))
    half = np.arcsin(np.minimum(1.0, FINE_SIGMAS * s / np.maximum(r, 1e-300)))
    phi, wp = split_nodes(np.full_like(x, -np.pi / 2), np.full_like(x, np.pi / 2), 0.0,
                          half / FINE_SIGMAS)
    wo = np.stack(np.broadcast_arrays(x[:, None], r[:, None] * np.sin(phi),
                                      r[:, None] * np.cos(phi)), -1).reshape(-1, 3)
    weight = (wx[:, None] * wp).ravel()
    keep = wo[:, 2] > 0
    f = brdf.eval_spectral(wi, wo[keep], lam)
    return float(np.sum(f * wo[keep, 2] * weight[keep]))


def hemisphere_energy(brdf, wi, lam, count=100):
    """int f cos_o d omega_o over the hemisphere on a uniform panel grid in
    (x, phi) (for broad lobes)."""
    x, wx = panels(-1.0, 1.0, count)
    phi, wp = panels(-np.pi / 2, np.pi / 2, count)
    r = np.sqrt(1.0 - x * x)[:, None]
    wo = np.stack(np.broadcast_arrays(x[:, None], r * np.sin(phi), r * np.cos(phi)),
                  -1).reshape(-1, 3)
    weight = (wx[:, None] * wp).ravel()
    return float(np.sum(brdf.eval_spectral(wi, wo, lam) * wo[:, 2] * weight))


def lobe_width(lam):
    """The lobe's standard deviation in direction cosine: the coherence window
    exp(-l^2 k^2 (u - u_n)^2) (docs/physics.md)."""
    k = 2 * np.pi / (lam * 1e-3)
    return 1.0 / (np.sqrt(2.0) * k * COHERENCE)


def incident(theta_deg):
    t = np.radians(theta_deg)
    return np.array([-np.sin(t), 0.0, np.cos(t)])


def kirchhoff_orders(brdf, lam, theta_deg):
    """{m: energy of order m} for every order whose window (its centre +- half
    an order spacing) meets the hemisphere; the windows tile it, so the sum is
    the directional albedo."""
    wi = incident(theta_deg)
    spacing = lam * 1e-3 / PERIOD
    s = lobe_width(lam)
    sin_t = -wi[0]
    out = {}
    m_lo = int(np.floor((-1 - sin_t) / spacing - 1))
    m_hi = int(np.ceil((1 - sin_t) / spacing + 1))
    for m in range(m_lo, m_hi + 1):
        c = sin_t + m * spacing
        lo, hi = max(-1.0, c - spacing / 2), min(1.0, c + spacing / 2)
        if hi > lo:
            out[m] = window_energy(brdf, wi, lam, lo, hi, c, s)
    return out


def rigorous_orders(lam, theta_deg, n):
    """{m: unpolarised efficiency}, {m: (s, p)} of the reflected orders."""
    r = core.rigorous_solve(**GEOMETRY, lambda_nm=lam, theta_deg=theta_deg, phi_deg=0.0,
                            orders=n)
    spacing = lam * 1e-3 / PERIOD
    sin_t = np.sin(np.radians(theta_deg))
    unpol, sp = {}, {}
    for o in r["reflected"]:
        m = o["m"]
        # the order-sign convention this script relies on
        assert abs(o["direction"][0] - (sin_t + m * spacing)) < 1e-9, o
        unpol[m] = 0.5 * (o["efficiency"][0] + o["efficiency"][1])
        sp[m] = tuple(o["efficiency"])
    return unpol, sp


# -- validation --------------------------------------------------------------------

def mc_albedo(brdf, wi, lam, n=400000, seed=1):
    """Directional albedo from the core's own sampling: mean of f cos / pdf
    (coherent samples: their reflectance over their probability)."""
    rnd = np.random.default_rng(seed).random((n, 3))
    wo, pdf, coh = brdf.sample(wi, rnd, np.full(n, lam))
    w = np.zeros(n)
    ok = (~coh) & (pdf > 0) & (wo[:, 2] > 0)
    w[ok] = brdf.eval_spectral(wi, wo[ok], lam) * wo[ok, 2] / pdf[ok]
    if coh.any():
        w[coh] = brdf.coherent_spectral(wi, lam) / pdf[coh]
    return w.mean(), w.std() / np.sqrt(n)


def rect_power(m, beta):
    """|c_m(beta)|^2 of the rect profile (docs/physics.md)."""
    d = WIDTH / PERIOD
    if m == 0:
        return abs(1 + (np.exp(1j * beta * HEIGHT) - 1) * d) ** 2
    return 4 * np.sin(beta * HEIGHT / 2) ** 2 * d * d * np.sinc(m * d) ** 2


def validate():
    print("## Validation of the lobe integration\n")
    # 1. A Gaussian rough surface (broad lobe, coherent lobe), Stam's formula,
    #    fresnel 1: the whole-hemisphere quadrature against the core's sampling
    #    and against docs/energy.md's furnace table (largest of 400/550/700 nm).
    b = core.Brdf({"surface": "gaussian", "sigma_um": 0.3, "corr_um": 2.0, "fresnel": 1.0,
                   "energy": "stam"})
    print("Gaussian sigma 0.3 um, T 2 um, fresnel 1, \"energy\": \"stam\": directional albedo "
          "(diffuse quadrature + coherent lobe) against the mean sample weight of the core's "
          "sampling (400 000 samples)\n")
    print("| cos_i | lambda nm | quadrature | sampled | difference / std. error |")
    print("|---|---|---|---|---|")
    worst = 0.0
    seed = 0
    for ci in (0.95, 0.7, 0.4):
        wi = np.array([-np.sqrt(1 - ci * ci), 0.0, ci])
        for lam in (400.0, 550.0, 700.0):
            q = hemisphere_energy(b, wi, lam) + float(b.coherent_spectral(wi, lam))
            seed += 1
            m, e = mc_albedo(b, wi, lam, seed=seed)
            worst = max(worst, abs(q - m))
            print("| %.2f | %.0f | %.4f | %.4f ± %.4f | %.1f |" % (ci, lam, q, m, e, (q - m) / e))
    print("\nlargest |quadrature - sampled|: %.4f (docs/energy.md's table, largest of the three "
          "wavelengths: 1.000, 0.981, 0.957)\n" % worst)

    # 2. The disc, Stam's formula, fresnel 1: each order's integral against the
    #    narrow-lobe closed form |c_m(k w)|^2 (1 + wi.wo)^2 / (cos_i cos_o w^2).
    b = core.Brdf({"surface": "cd", "energy": "stam", "fresnel": 1.0})
    worst = 0.0
    for lam in WAVELENGTHS:
        k = 2 * np.pi / (lam * 1e-3)
        for th in TABLE_ANGLES:
            wi = incident(th)
            for m, e in kirchhoff_orders(b, lam, th).items():
                c = -wi[0] + m * lam * 1e-3 / PERIOD
                if abs(c) > 0.99:
                    continue
                wo = np.array([c, 0.0, np.sqrt(1 - c * c)])
                w = wi[2] + wo[2]
                closed = rect_power(m, k * w) * (1 + wi @ wo) ** 2 / (wi[2] * wo[2] * w * w)
                if closed > 1e-3:
                    worst = max(worst, abs(e - closed) / closed)
    print("Disc, \"stam\", fresnel 1, every order with energy > 0.001 and |wo_x| < 0.99 at the "
          "table's 12 points: largest relative difference of the lobe integral from the "
          "narrow-lobe closed form |c_m(kw)|^2 (1 + wi.wo)^2 / (cos_i cos_o w^2): %.1e\n" % worst)

    # 3. The disc as rendered (aluminium): the sum over the orders' windows
    #    against the core's sampling.
    print("Disc (aluminium): sum over the orders' lobes against the mean sample weight of the "
          "core's sampling (400 000 samples)\n")
    print("| energy | lambda nm | theta | sum over orders | sampled | difference / std. error |")
    print("|---|---|---|---|---|---|")
    for mode in MODES:
        b = core.Brdf({"surface": "cd", "energy": mode})
        for lam in (450.0, 650.0):
            for th in (0.0, 30.0, 75.0):
                q = sum(kirchhoff_orders(b, lam, th).values())
                seed += 1
                m, e = mc_albedo(b, incident(th), lam, seed=seed)
                print("| %s | %.0f | %.0f | %.4f | %.4f ± %.4f | %.1f |"
                      % (mode, lam, th, q, m, e, (q - m) / e))
    print()


# -- main ------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--step", type=float, default=1.0, help="incidence step, degrees")
    ap.add_argument("--out", default=str(ROOT / "docs"), help="folder for the figures")
    ap.add_argument("--no-validate", action="store_true")
    args = ap.parse_args()
    t_start = time.time()

    brdfs = {mode: core.Brdf({"surface": "cd", "energy": mode}) for mode in MODES}
    for mode, b in brdfs.items():
        p = b.resolved_params()
        assert (p["period_um"], p["height_um"], p["width_um"], p["coherence_um"], p["profile"],
                p["fresnel"]) == (PERIOD, HEIGHT, WIDTH, COHERENCE, "rect", "aluminium"), p

    if not args.no_validate:
        validate()
        print("(validation: %.0f s)\n" % (time.time() - t_start))

    angles = np.arange(0.0, 80.0 + 1e-9, args.step)
    angles = np.union1d(angles, TABLE_ANGLES)
    sweep = {}  # (lam, theta) -> dict
    t0 = time.time()
    for lam in WAVELENGTHS:
        for th in angles:
            rig, sp = rigorous_orders(lam, th, N_RIGOROUS)
            coarse, _ = rigorous_orders(lam, th, N_COARSE)
            sweep[lam, th] = dict(rig=rig, sp=sp, coarse=coarse,
                                  **{mode: kirchhoff_orders(brdfs[mode], lam, th)
                                     for mode in MODES})
    print("(sweep of %d points: %.0f s)\n" % (len(sweep), time.time() - t0))

    # -- convergence
    print("## Convergence of the rigorous solve\n")
    d40 = max(abs(v["rig"][m] - v["coarse"].get(m, 0.0)) for v in sweep.values() for m in v["rig"])
    where = max(((abs(v["rig"][m] - v["coarse"].get(m, 0.0)), key, m)
                 for key, v in sweep.items() for m in v["rig"]))
    print("N = %d against N = %d, every order at every point of the sweep (%d points): largest "
          "change of an unpolarised efficiency %.5f (%.0f nm, %.0f deg, order %+d)"
          % (N_COARSE, N_RIGOROUS, len(sweep), d40, where[1][0], where[1][1], where[2]))
    fine, _ = rigorous_orders(where[1][0], where[1][1], N_FINE)
    print("  there, N = %d against N = %d: %.5f"
          % (N_RIGOROUS, N_FINE, max(abs(fine[m] - sweep[where[1]]["rig"][m]) for m in fine)))
    d160, d160sp = 0.0, 0.0
    for lam in WAVELENGTHS:
        for th in TABLE_ANGLES:
            fine, fsp = rigorous_orders(lam, th, N_FINE)
            v = sweep[lam, th]
            for m in fine:
                d160 = max(d160, abs(fine[m] - v["rig"][m]))
                d160sp = max(d160sp, *(abs(a - b) for a, b in zip(fsp[m], v["sp"][m])))
    print("N = %d against N = %d at the table's 12 points: largest change %.5f unpolarised, "
          "%.5f in s or p\n" % (N_RIGOROUS, N_FINE, d160, d160sp))

    # -- tables
    print("## Per-order efficiency (rigorous N = %d; Kirchhoff = the core's BRDF over each "
          "order's lobe)\n" % N_RIGOROUS)
    print("Orders with more than 0.01 in any of the three; difference = Kirchhoff - rigorous.\n")
    print("| lambda nm | theta | order | rigorous (s, p) | rigorous | stam | conserving "
          "| stam - rig. | cons. - rig. |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = {mode: (0.0, None) for mode in MODES}
    totals = []
    for lam in WAVELENGTHS:
        for th in TABLE_ANGLES:
            v = sweep[lam, th]
            ms = sorted(set(v["rig"]) | set(v["stam"]))
            for m in ms:
                r = v["rig"].get(m, 0.0)
                ks, kc = v["stam"].get(m, 0.0), v["conserving"].get(m, 0.0)
                for mode, k in (("stam", ks), ("conserving", kc)):
                    if abs(k - r) > worst[mode][0]:
                        worst[mode] = (abs(k - r), (lam, th, m, r, k))
                if max(r, ks, kc) <= 0.01:
                    continue
                s, p = v["sp"].get(m, (0.0, 0.0))
                print("| %.0f | %.0f | %+d | %.3f, %.3f | %.3f | %.3f | %.3f | %+.3f | %+.3f |"
                      % (lam, th, m, s, p, r, ks, kc, ks - r, kc - r))
            tr, ts, tc = (sum(v[key].values()) for key in ("rig", "stam", "conserving"))
            totals.append((lam, th, tr, ts, tc))
    print()
    for mode in MODES:
        e, (lam, th, m, r, k) = worst[mode]
        print("worst single-order |difference|, %s: %.3f (%.0f nm, %.0f deg, order %+d: "
              "%.3f against %.3f rigorous)" % (mode, e, lam, th, m, k, r))
    print("\n## Total reflected (sum over the orders)\n")
    print("| lambda nm | theta | rigorous | stam | conserving | stam - rig. | cons. - rig. |")
    print("|---|---|---|---|---|---|---|")
    for lam, th, tr, ts, tc in totals:
        print("| %.0f | %.0f | %.3f | %.3f | %.3f | %+.3f | %+.3f |"
              % (lam, th, tr, ts, tc, ts - tr, tc - tr))
    print()
    for i, mode in enumerate(MODES):
        ex = max(totals, key=lambda t: t[3 + i] - t[2])
        print("largest total excess over rigorous at the table's points, %s: %+.3f "
              "(%.0f nm, %.0f deg)" % (mode, ex[3 + i] - ex[2], ex[0], ex[1]))

    # over the whole sweep
    print("\n## Over the whole sweep (incidence 0-80 deg, step %g)\n" % args.step)
    for mode in MODES:
        e_o = max((abs(v[mode].get(m, 0.0) - v["rig"].get(m, 0.0)), key, m)
                  for key, v in sweep.items() for m in set(v["rig"]) | set(v[mode]))
        e_t = max((sum(v[mode].values()) - sum(v["rig"].values()), key)
                  for key, v in sweep.items())
        print("%s: worst single-order |difference| %.3f (%.0f nm, %.0f deg, order %+d); "
              "largest total excess %+.3f (%.0f nm, %.0f deg)"
              % (mode, e_o[0], e_o[1][0], e_o[1][1], e_o[2], e_t[0], e_t[1][0], e_t[1][1]))
    big = sorted({m for v in sweep.values() for m, r in v["rig"].items() if r > 0.02})
    print("orders with rigorous efficiency > 0.02 somewhere in the sweep: %s (plotted: %s)"
          % (", ".join("%+d" % m for m in big), ", ".join("%+d" % m for m in PLOT_ORDERS)))

    plot(sweep, angles, Path(args.out))
    print("\n(total: %.0f s)" % (time.time() - t_start))


def plot(sweep, angles, out):
    colours = {-2: "#7b3294", -1: "#2c7bb6", 0: "#333333", 1: "#d7191c", 2: "#e08214"}
    series = lambda lam, key, m: np.array([sweep[lam, th][key].get(m, 0.0) for th in angles])

    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5), sharex=True, sharey=True)
    for row, mode in enumerate(MODES):
        for col, lam in enumerate(WAVELENGTHS):
            ax = axes[row, col]
            for m in PLOT_ORDERS:
                ax.plot(angles, series(lam, "rig", m), "-", color=colours[m], lw=1.6,
                        label="%+d rigorous" % m if m else "0 rigorous")
                ax.plot(angles, series(lam, mode, m), "--", color=colours[m], lw=1.2,
                        label="%+d Kirchhoff" % m if m else "0 Kirchhoff")
            ax.set_title('%.0f nm, Kirchhoff "energy": "%s"' % (lam, mode), fontsize=10)
            ax.grid(alpha=0.3)
            if row == 1:
                ax.set_xlabel("incidence (degrees, plane across the grooves)")
            if col == 0:
                ax.set_ylabel("order efficiency (unpolarised)")
    axes[0, 0].set_ylim(0, None)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=9, frameon=False)
    fig.suptitle("Compact disc (rect Al bumps 0.15 x 0.5 um, period 2.5 um): rigorous RCWA "
                 "(solid, N = %d) against the core's Kirchhoff BRDF integrated over each "
                 "order's lobe (dashed)\norder m leaves at sin th + m lambda / period "
                 "(+1: towards grazing on the far side, -1: back towards the light)"
                 % N_RIGOROUS, fontsize=10)
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    fig.savefig(out / "rigorous_orders.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4), sharey=True)
    for ax, lam in zip(axes, WAVELENGTHS):
        tot = lambda key: np.array([sum(sweep[lam, th][key].values()) for th in angles])
        ax.plot(angles, tot("rig"), "-", color="k", lw=1.8, label="rigorous (RCWA)")
        ax.plot(angles, tot("stam"), "--", color="#d7191c", lw=1.3, label='Kirchhoff, "stam"')
        ax.plot(angles, tot("conserving"), "--", color="#2c7bb6", lw=1.3,
                label='Kirchhoff, "conserving" (default)')
        ax.axhline(1.0, color="0.6", lw=0.8)
        ax.set_title("%.0f nm: total reflected" % lam, fontsize=10)
        ax.set_xlabel("incidence (degrees, plane across the grooves)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("sum over the orders")
    axes[0].legend(fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "rigorous_totals.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
