#!/usr/bin/env python3
"""make_wear_map.py: write scenes/textures/wear_map.exr, the sigma map of
scenes/gaussian_wear_map.xml: a polished metal (rms height 0.012 um, a
mirror) with scratches (0.1-0.3 um, glossy) and a worn, hazy patch
(up to 0.08 um). The values are sigma_um in micrometres (a raw
single-channel float texture); the pattern is seeded, so the file is the
same on every run.

Run from the repository root: .venv/bin/python scripts/make_wear_map.py [--size N]
"""

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))

POLISHED_UM = 0.012
HAZE_UM = 0.08


def wear_map(size, seed=7):
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:size, 0:size] / size
    sigma = np.full((size, size), POLISHED_UM)
    # A worn patch: haze falling off smoothly from an off-centre spot
    d2 = ((u - 0.62) ** 2 + (v - 0.38) ** 2) / 0.18 ** 2
    sigma += (HAZE_UM - POLISHED_UM) * np.exp(-d2)
    # Scratches: straight segments, mostly along one direction (wiping)
    for _ in range(30):
        a = rng.uniform(0, 1, 2)
        angle = rng.normal(0.35, 0.25) * np.pi
        length = rng.uniform(0.15, 0.6)
        b = a + length * np.array([np.cos(angle), np.sin(angle)])
        depth = rng.uniform(0.1, 0.3)
        width = rng.uniform(0.6, 1.6) / size
        ab = b - a
        t = np.clip(((u - a[0]) * ab[0] + (v - a[1]) * ab[1]) / (ab @ ab), 0, 1)
        dist = np.hypot(u - a[0] - t * ab[0], v - a[1] - t * ab[1])
        sigma = np.maximum(sigma, depth * np.exp(-0.5 * (dist / width) ** 2))
    return sigma.astype(np.float32)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--size', type=int, default=256)
    ap.add_argument('--out', default=os.path.join(ROOT, 'scenes', 'textures', 'wear_map.exr'))
    args = ap.parse_args(argv)
    import stam_mitsuba
    mi = stam_mitsuba.setup('scalar_rgb')
    sigma = wear_map(args.size)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    # half floats: 1e-3 relative, a quarter of the file of float32 uncompressed
    mi.Bitmap(sigma[..., None].astype(np.float16)).write(args.out)
    print('wrote %s: %dx%d, sigma_um %.3f..%.3f (mean %.3f)'
          % (args.out, args.size, args.size, sigma.min(), sigma.max(), sigma.mean()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
