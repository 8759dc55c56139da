#!/usr/bin/env python3
"""Plot the white furnace (directional albedo against the incidence cosine) of
`rust-core/examples/furnace.rs`, Stam's formula against the energy-conserving
material, for every test material.

usage: plot_furnace.py target/furnace/albedo.json docs/img/energy_furnace.png
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    rows = json.load(open(sys.argv[1]))
    out = sys.argv[2]
    channels = sorted({r["channel"] for r in rows})
    materials = list(dict.fromkeys(r["material"] for r in rows))
    fig, axes = plt.subplots(1, len(channels), figsize=(6 * len(channels), 5), sharey=True)
    if len(channels) == 1:
        axes = [axes]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, channel in zip(axes, channels):
        for i, material in enumerate(materials):
            for mode, style in [("stam", "--"), ("conserving", "-")]:
                pts = sorted(
                    (r["cos_i"], r["albedo"], r["se"])
                    for r in rows
                    if r["channel"] == channel and r["material"] == material and r["mode"] == mode
                )
                if not pts:
                    continue
                x, y, e = zip(*pts)
                ax.errorbar(x, y, yerr=[3 * v for v in e], fmt=style, marker="o", ms=3,
                            color=colours[i % len(colours)],
                            label=f"{material} ({mode})" if ax is axes[0] else None)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cos theta_i")
        ax.set_title(channel)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("directional albedo (fresnel = 1), error bars 3 SE")
    fig.legend(loc="lower center", ncol=3, fontsize=7)
    fig.tight_layout(rect=(0, 0.18, 1, 1))
    fig.savefig(out, dpi=110)
    print("wrote", out)


if __name__ == "__main__":
    main()
