#!/usr/bin/env python3
"""Plots of the Kirchhoff ground-truth run (docs/kirchhoff.md).

Reads docs/kirchhoff-data/*.csv written by `cargo run --release -p kirchhoff -- --full`
and writes docs/img/kirchhoff_*.png. Run from the repository root (or pass it).
"""
import csv
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent
DATA = ROOT / "docs" / "kirchhoff-data"
IMG = ROOT / "docs" / "img"


def read(name):
    with open(DATA / name, newline="") as f:
        return list(csv.DictReader(f))


def by_case(rows):
    d = defaultdict(list)
    for r in rows:
        d[r["case"]].append(r)
    return d


def fl(r, k):
    return float(r[k])


def ratio_panel(ax, cases, title, xkey="u", xlabel="u = |q| / k0", cut=None):
    for name, rows in cases.items():
        rows = [r for r in rows if r["cut"] != "q0" and (cut is None or r["cut"] == cut)]
        res = [r for r in rows if r["resolved"] == "1"]
        if not res:
            continue
        x = [fl(r, xkey) for r in res]
        y = [fl(r, "ratio") for r in res]
        e = [fl(r, "ratio_err") for r in res]
        ax.errorbar(x, y, yerr=e, fmt="o-", ms=3, capsize=2, lw=0.8, label=name)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhspan(0.95, 1.05, color="0.9", zorder=0)
    ax.set_ylim(0.93, 1.07)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("core / ground truth")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=6)


def main():
    IMG.mkdir(parents=True, exist_ok=True)
    rows = read("random_bins.csv")
    cases = by_case(rows)
    iso = {k: v for k, v in cases.items() if v[0]["model"] == "gaussian-iso"}
    aniso = {k: v for k, v in cases.items() if v[0]["model"] == "gaussian-aniso"}
    fbm = {k: v for k, v in cases.items() if v[0]["model"] == "fractal"}

    # 1. Gaussian isotropic: ratio per bin, normal and oblique.
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, th in zip(axes, ["0", "40"]):
        sel = {k: v for k, v in iso.items() if v[0]["theta_i"] == th}
        ratio_panel(ax, sel, f"Gaussian isotropic, theta_i = {th} deg")
    fig.tight_layout()
    fig.savefig(IMG / "kirchhoff_gaussian_iso.png", dpi=90)
    plt.close(fig)

    # 2. Anisotropic: x and y cuts.
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, cut in zip(axes, ["x", "y"]):
        ratio_panel(ax, aniso, f"Gaussian anisotropic, {cut} cut", xkey="q",
                    xlabel="rho = |(q_x T_x, q_y T_y)|", cut=cut)
    fig.tight_layout()
    fig.savefig(IMG / "kirchhoff_gaussian_aniso.png", dpi=90)
    plt.close(fig)

    # 3. Fractal: ratio per bin and the spectra.
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    ratio_panel(axes[0], fbm, "fractional Brownian", xkey="q", xlabel="|q| (1/um)")
    axes[0].set_xscale("log")
    for name, rs in fbm.items():
        if "th=0" not in name:
            continue
        rs = [r for r in rs if r["cut"] == "ring"]
        q = [fl(r, "q") for r in rs]
        axes[1].loglog(q, [fl(r, "gt") for r in rs], "o", ms=3, label=f"GT {name}")
        axes[1].loglog(q, [fl(r, "core") for r in rs], "-", lw=0.8)
    axes[1].set_xlabel("|q| (1/um)")
    axes[1].set_ylabel("<|P|^2>/A (um^2): points GT, lines core")
    axes[1].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(IMG / "kirchhoff_fractal.png", dpi=90)
    plt.close(fig)

    # 4. Approximations (Gaussian isotropic): where Beckmann and first order hold.
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, key, title in [(axes[0], "beckmann_ratio", "Beckmann (large-g limit)"),
                           (axes[1], "first_order_ratio", "first order (m = 1 term)")]:
        for name, rs in iso.items():
            res = [r for r in rs if r["resolved"] == "1" and r["cut"] == "ring"]
            if not res:
                continue
            g = fl(res[0], "roughness")
            ax.semilogy([fl(r, "u") for r in res], [max(fl(r, key), 1e-6) for r in res], "o-", ms=3,
                        lw=0.8, label=f"g = {g:.3g} ({name.split()[-1]})")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.axhspan(0.95, 1.05, color="0.85", zorder=0)
        ax.set_ylim(1e-3, 1e3)
        ax.set_xlabel("u = |q| / k0")
        ax.set_ylabel("approximation / ground truth")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(IMG / "kirchhoff_approximations.png", dpi=90)
    plt.close(fig)

    # 5. Periodic: scans (GT vs core) and the ratio off the peaks.
    scan = by_case(read("periodic_scan.csv"))
    names = [n for n in scan if "th=0" in n]
    fig, axes = plt.subplots(2, len(names), figsize=(4.2 * len(names), 6.5), squeeze=False)
    for i, name in enumerate(names):
        rs = scan[name]
        q = [fl(r, "qx") for r in rs]
        gt = [fl(r, "gt") for r in rs]
        core = [fl(r, "core") for r in rs]
        peak = fl(rs[0], "peak_max")
        ax = axes[0][i]
        ax.semilogy(q, gt, "-", lw=1.5, label="ground truth")
        ax.semilogy(q, core, "--", lw=1.0, label="core")
        ax.set_ylim(peak * 1e-12, peak * 3)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("q_x (1/um)")
        ax.set_ylabel("<|P|^2>/A (um^2)")
        ax.legend(fontsize=6)
        ax = axes[1][i]
        sel = [(a, abs(c / b - 1) + 1e-12, b / peak) for a, b, c in zip(q, gt, core) if b > 0]
        res = [t for t in sel if t[2] > 1e-6]
        low = [t for t in sel if t[2] <= 1e-6]
        ax.semilogy([t[0] for t in res], [t[1] for t in res], ".", ms=2, label="GT > 1e-6 peak (resolved)")
        ax.semilogy([t[0] for t in low], [t[1] for t in low], ".", ms=2, color="0.7",
                    label="GT < 1e-6 peak (cross terms, round-off)")
        ax.set_ylabel("abs(core / GT - 1)")
        ax.set_xlabel("q_x (1/um)")
        ax.axhline(1e-4, color="r", lw=0.8)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(IMG / "kirchhoff_periodic.png", dpi=90)
    plt.close(fig)

    # 6. Height maps: core / GT per resolved bin against its brightness.
    maps_file = DATA / "heightmap_bins.csv"
    if maps_file.exists():
        maps = by_case(read("heightmap_bins.csv"))
        fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        for ax, demo in zip(axes, (False, True)):
            for name, rs in maps.items():
                if name.startswith("demo") != demo:
                    continue
                peak = max(fl(r, "gt_um2") for r in rs)
                res = [r for r in rs if r["resolved"] == "1"]
                if not res:
                    continue
                x = [fl(r, "gt_um2") / peak for r in res]
                y = [fl(r, "core_um2") / fl(r, "gt_um2") for r in res]
                e = [fl(r, "gt_se_um2") / fl(r, "gt_um2") * yy for r, yy in zip(res, y)]
                ax.errorbar(x, y, yerr=e, fmt="o", ms=3, capsize=2, lw=0.8, label=name)
            ax.set_xscale("log")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.set_ylim(0.8, 1.2)
            ax.set_xlabel("bin / brightest bin")
            ax.set_title("demo maps (scenes/heightmaps)" if demo else "CI maps (synthetic)", fontsize=10)
            ax.legend(fontsize=6)
        axes[0].set_ylabel("core / Kirchhoff over the map's tiles")
        fig.tight_layout()
        fig.savefig(IMG / "kirchhoff_heightmap.png", dpi=90)
        plt.close(fig)
    print("wrote", *sorted(p.name for p in IMG.glob("kirchhoff_*.png")))


if __name__ == "__main__":
    main()
