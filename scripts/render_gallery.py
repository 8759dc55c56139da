#!/usr/bin/env python3
"""render_gallery.py: render the paper's subjects (scenes/hero_*.xml) with the
`diffraction` plugin to out/gallery/<name>.{exr,png}, write a labelled contact
sheet out/gallery/contact_sheet.png, print progress, timings and, with
--noise, each render's seed-to-seed noise.

    make demo                                   # setup + core + plugin + this
    .venv/bin/python scripts/render_gallery.py [--quick] [--only hero_cd,hero_sweep]
                                               [--classic] [--noise] [--out DIR]

The heroes (docs/gallery.md): a compact disc with its hole, clamping ring and
a labelled disc beside it under studio strip lights; five Gaussian spheres
from mirror to rough with diffraction halos; a disc of brushed aluminium
(concentric brushing); a fractal silver sphere. All render in scalar_rgb (the
core integrates each spectrum, a grating's orders exactly: no wavelength
noise) with a multi-jittered sampler. --classic adds the small scenes of
earlier versions (cd.xml in both variants, grating, gaussian_smooth, brushed,
fractal, sweep), the twist-map scene (brushed_twist_map) and the sigma- and
height-map scenes (gaussian_wear_map, cd_depth_map; llvm_ad_spectral: these
textures need a JIT variant). The studio environment and the disc's label
are made by scripts/studio_env.py (out/env/).

--noise renders every scene a second time with another seed and prints the
relative difference over lit pixels, mean |a - b| / mean a over the pixels
brighter than 5 % of the 99th percentile of luminance (docs/gallery.md).

PNGs are linear renders exposed so that a high percentile of the image maps
to 0.9, then sRGB-encoded; the EXRs are the raw linear renders.
"""

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import stam_mitsuba  # noqa: E402
import stam_images  # noqa: E402
import studio_env  # noqa: E402

SCENES_DIR = os.path.join(ROOT, 'scenes')
OUT_DIR = os.path.join(ROOT, 'out', 'gallery')

# name, scene file, variant, label, scene parameters, exposure percentile
HEROES = [
    # spp: multijitter rounds the count to a product of two near factors; 528 = 22 x 24.
    ('hero_cd', 'hero_cd.xml', 'scalar_rgb',
     'Compact disc (Stam\'s dimensions: pitch 2.5 um, bumps 0.15 x 0.5 um), '
     'concentric tracks, studio strip lights; a labelled disc beside it',
     dict(res=512, spp=528), 99.5),
    ('hero_sweep', 'hero_sweep.xml', 'scalar_rgb',
     'Gaussian spheres, T 0.5 um, sigma 0.003 / 0.012 / 0.025 / 0.05 / 0.15 um: '
     'mirror, diffraction halos, rough',
     dict(res=512, width=1152, spp=100), 99.5),
    ('hero_brushed', 'hero_brushed.xml', 'scalar_rgb',
     'Brushed aluminium disc, concentric: sigma 0.08, T 1 um across, 30 um along',
     dict(res=512, spp=132), 98.0),
    ('hero_fractal', 'hero_fractal.xml', 'scalar_rgb',
     'Fractal silver, sigma 0.05 um over 1 um, H 0.5: sphere and plate',
     dict(res=512, spp=224), 99.5),
]

CLASSIC = [
    ('cd', 'cd.xml', 'scalar_spectral',
     'Compact disc (Stam\'s dimensions), small light, scalar_spectral',
     dict(res=256, spp=32), 99.7),
    ('cd_rgb', 'cd.xml', 'scalar_rgb',
     'Compact disc, scalar_rgb (out-of-gamut colours gamut-mapped)',
     dict(res=256, spp=16), 99.7),
    ('grating', 'grating.xml', 'scalar_spectral',
     'Sine grating, 3 um, gold, scalar_spectral',
     dict(res=256, spp=24), 99.7),
    ('gaussian_smooth', 'gaussian_smooth.xml', 'scalar_spectral',
     'Isotropic Gaussian, sigma 0.06, T 1 um: coherent + diffuse lobe',
     dict(res=256, spp=32), 99.0),
    ('brushed', 'brushed.xml', 'scalar_spectral',
     'Brushed: Tx 1.5, Ty 25 um, twist 30 deg',
     dict(res=256, spp=32), 99.5),
    ('fractal', 'fractal.xml', 'scalar_spectral',
     'Fractal, H 0.5, silver: peak with long tails',
     dict(res=256, spp=32), 99.0),
    ('brushed_twist_map', 'brushed_twist_map.xml', 'scalar_spectral',
     'Brushed tiles: a twist map (checkerboard texture of 0 and 90 deg)',
     dict(res=256, spp=32), 99.5),
    ('gaussian_wear_map', 'gaussian_wear_map.xml', 'llvm_ad_spectral',
     'Polished aluminium with a wear map: sigma_um a texture (0.012 um polished, '
     '0.1-0.3 um scratches)',
     dict(res=256, spp=64), 99.5),
    ('cd_depth_map', 'cd_depth_map.xml', 'llvm_ad_spectral',
     'Compact disc whose groove depth is a texture: sectors of 0.08 and 0.22 um',
     dict(res=256, spp=128), 99.5),
    ('sweep', 'sweep.xml', 'scalar_spectral',
     'Sweep sigma/lambda 0.01..1, T 4 um',
     dict(res=160, width=400, spp=32), 99.0),
]
GALLERY = HEROES + CLASSIC


def relative_noise(a, b):
    """Seed-to-seed noise of two renders: mean |a - b| / mean a over the lit
    pixels (luminance above 5 % of its 99th percentile)."""
    lum = a[..., :3].mean(axis=-1)
    lit = lum > 0.05 * np.percentile(lum, 99)
    return float(np.abs(a - b)[lit].mean() / max(a[lit].mean(), 1e-30))


def render_one(name, scene_file, variant, params, percentile, out_dir, seed=0):
    mi = stam_mitsuba.setup(variant)
    studio_env.write()
    # Loaded in order, so that a scene's kernels are the same from run to run
    # and come from Dr.Jit's cache (docs/guide.md)
    scene = mi.load_file(os.path.join(SCENES_DIR, scene_file), parallel=False,
                         **{k: v for k, v in params.items()})
    t0 = time.time()
    img = np.array(mi.render(scene, seed=seed), dtype=np.float32)
    dt = time.time() - t0
    if not np.all(np.isfinite(img)):
        raise RuntimeError('%s: render has non-finite pixels' % name)
    exr = os.path.join(out_dir, name + '.exr')
    png = os.path.join(out_dir, name + '.png')
    stam_images.save_exr(mi, exr, img)
    stam_images.save_png(png, img, stam_images.auto_exposure(img, percentile))
    return png, dt, img


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true',
                    help='quarter the samples and halve the resolution (smoke test)')
    ap.add_argument('--only', default='', help='comma-separated scene names')
    ap.add_argument('--classic', action='store_true',
                    help='also render the small scenes of earlier versions')
    ap.add_argument('--noise', action='store_true',
                    help='render each scene again with another seed and print the noise')
    ap.add_argument('--out', default=OUT_DIR)
    args = ap.parse_args(argv)

    items = GALLERY if args.classic else HEROES
    if args.only:
        want = set(args.only.split(','))
        unknown = want - {g[0] for g in GALLERY}
        if unknown:
            ap.error('unknown scene(s): %s' % ', '.join(sorted(unknown)))
        items = [g for g in GALLERY if g[0] in want]
    os.makedirs(args.out, exist_ok=True)

    t_all = time.time()
    sheet = []
    for k, (name, scene_file, variant, label, params, pct) in enumerate(items):
        params = dict(params)
        if args.quick:
            params['spp'] = max(4, params['spp'] // 4)
            for key in ('res', 'width'):
                if key in params:
                    params[key] //= 2
        size = '%sx%s' % (params.get('width', params['res']), params['res'])
        print('[gallery] (%d/%d) %-16s %-16s %s, %d spp ...' % (
            k + 1, len(items), name, variant, size, params['spp']), end='', flush=True)
        png, dt, img = render_one(name, scene_file, variant, params, pct, args.out)
        note = ''
        if args.noise:
            mi = stam_mitsuba.setup(variant)
            scene = mi.load_file(os.path.join(SCENES_DIR, scene_file), parallel=False,
                                 **params)
            other = np.array(mi.render(scene, seed=1), dtype=np.float32)
            note = ', noise %.1f %%' % (100 * relative_noise(img, other))
        print(' %.1f s%s' % (dt, note), flush=True)
        sheet.append(('%s\n%s, %s, %d spp, %.0f s%s' % (label, variant, size, params['spp'],
                                                       dt, note), png))
    total = time.time() - t_all
    cs = os.path.join(args.out, 'contact_sheet.png')
    stam_images.contact_sheet(cs, [(lbl, p) for lbl, p in sheet],
                              columns=min(len(sheet), 4 if args.classic else 2), tile=400,
                              title="Stam, Diffraction Shaders (SIGGRAPH 1999) in Mitsuba 3: "
                                    "the `diffraction` BSDF")
    print('[gallery] wrote %d renders (PNG + EXR) and %s' % (len(sheet), cs))
    print('[gallery] total render time %.1f s' % total)
    return 0


if __name__ == '__main__':
    sys.exit(main())
