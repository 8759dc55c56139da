#!/usr/bin/env python3
"""render_gallery.py: render every scene of scenes/ (the paper's figures) with the
`diffraction` plugin to out/gallery/<name>.{exr,png}, write a labelled contact
sheet out/gallery/contact_sheet.png, print progress and the total time.

    make demo                                   # setup + core + plugin + this
    .venv/bin/python scripts/render_gallery.py [--quick] [--only cd,sweep]

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

SCENES_DIR = os.path.join(ROOT, 'scenes')
OUT_DIR = os.path.join(ROOT, 'out', 'gallery')

# name, scene file, variant, label, scene parameters, exposure percentile
GALLERY = [
    ('cd', 'cd.xml', 'scalar_spectral',
     'Compact disc (Stam\'s dimensions)\nscalar_spectral',
     dict(res=256, spp=32), 99.7),
    ('cd_rgb', 'cd.xml', 'scalar_rgb',
     'Compact disc, scalar_rgb\n(out-of-gamut colours gamut-mapped)',
     dict(res=256, spp=16), 99.7),
    ('grating', 'grating.xml', 'scalar_spectral',
     'Sine grating, 3 um, gold\nscalar_spectral',
     dict(res=256, spp=24), 99.7),
    ('gaussian_smooth', 'gaussian_smooth.xml', 'scalar_spectral',
     'Isotropic Gaussian, s 0.06, T 1 um\ncoherent + diffuse lobe',
     dict(res=256, spp=32), 99.0),
    ('brushed', 'brushed.xml', 'scalar_spectral',
     'Brushed: Tx 1.5, Ty 25 um\ntwist 30 deg',
     dict(res=256, spp=32), 99.5),
    ('fractal', 'fractal.xml', 'scalar_spectral',
     'Fractal, H 0.5, silver\npeak with long tails',
     dict(res=256, spp=32), 99.0),
    ('sweep', 'sweep.xml', 'scalar_spectral',
     'Sweep sigma/lambda 0.01..1\nmirror -> colours -> rough',
     dict(res=160, width=400, spp=32), 99.0),
]


def render_one(name, scene_file, variant, params, percentile, out_dir):
    mi = stam_mitsuba.setup(variant)
    scene = mi.load_file(os.path.join(SCENES_DIR, scene_file),
                         **{k: v for k, v in params.items()})
    t0 = time.time()
    img = np.array(mi.render(scene), dtype=np.float32)
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
    ap.add_argument('--out', default=OUT_DIR)
    args = ap.parse_args(argv)

    items = GALLERY
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
        png, dt, _ = render_one(name, scene_file, variant, params, pct, args.out)
        print(' %.1f s' % dt, flush=True)
        first, second = (label.split('\n') + [variant])[:2]
        sheet.append(('%s\n%s, %.0f s' % (first, second, dt), png))
    total = time.time() - t_all
    cs = os.path.join(args.out, 'contact_sheet.png')
    stam_images.contact_sheet(cs, [(lbl, p) for lbl, p in sheet], columns=4, tile=256,
                              title="Stam, Diffraction Shaders (SIGGRAPH 1999) in Mitsuba 3: "
                                    "the `diffraction` BSDF")
    print('[gallery] wrote %d renders (PNG + EXR) and %s' % (len(sheet), cs))
    print('[gallery] total render time %.1f s' % total)
    return 0


if __name__ == '__main__':
    sys.exit(main())
