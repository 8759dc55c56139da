#!/usr/bin/env python3
"""Reads criterion's estimates for the `eval` group (cargo bench --bench brdf)
and prints/writes the ns-per-evaluation table with ratios to the
Cook-Torrance/Beckmann baseline measured in the same run."""
import json
import pathlib
import sys

BATCH = 1024  # evaluations per criterion iteration (benches/brdf.rs)
root = pathlib.Path(__file__).resolve().parent.parent
group = root / "target" / "criterion" / "eval"


def ns_per_eval(bench_dir):
    est = json.loads((bench_dir / "new" / "estimates.json").read_text())
    return est["median"]["point_estimate"] / BATCH


def main():
    baseline = ns_per_eval(group / "baseline_cook_torrance")
    # criterion flattens "name/mode" into the directory "name_mode".
    names = sorted({p.name.rsplit("_", 1)[0] for p in group.iterdir()
                    if p.is_dir() and p.name.rsplit("_", 1)[-1] in ("spectral", "rgb")})
    rows = []
    for name in names:
        row = [name]
        for mode in ("spectral", "rgb"):
            d = group / f"{name}_{mode}"
            if (d / "new" / "estimates.json").exists():
                ns = ns_per_eval(d)
                row += [f"{ns:.0f}", f"{ns / baseline:.1f}x"]
            else:
                row += ["-", "-"]
        rows.append(row)
    lines = [
        f"Baseline (Cook-Torrance, Beckmann, Smith, conductor Fresnel): {baseline:.1f} ns per evaluation.",
        "",
        "| material | spectral ns | spectral / baseline | RGB ns | RGB / baseline |",
        "|---|---|---|---|---|",
    ] + ["| " + " | ".join(r) + " |" for r in rows]
    text = "\n".join(lines)
    print(text)
    if len(sys.argv) > 1:
        out = pathlib.Path(sys.argv[1])
        marker = "<!-- bench-table -->"
        doc = out.read_text() if out.exists() else f"{marker}\n{marker}\n"
        head, _, rest = doc.partition(marker)
        _, _, tail = rest.partition(marker)
        out.write_text(f"{head}{marker}\n{text}\n{marker}{tail}")


if __name__ == "__main__":
    main()
