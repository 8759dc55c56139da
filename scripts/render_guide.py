#!/usr/bin/env python3
"""render_guide.py: the pictures of docs/guide.md, rendered with the
`diffraction` plugin and written to docs/img/guide/<figure>.png (one
labelled strip or grid per figure; the tiles go to out/guide/).

    make guide                                   # = plugin + this script
    .venv/bin/python scripts/render_guide.py [--quick] [--only discs,tracks]

Renders are small (128-160 pixels, 16-256 spp): all figures take a minute
or two on two cores. Each figure says whether its tiles share one exposure
(brightness compares across them) or are exposed each on its own. The script also prints the
seed-to-seed noise of the RGB and spectral renders of the disc that
docs/guide.md quotes.
"""

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import stam_images  # noqa: E402
import stam_mitsuba  # noqa: E402

OUT_TILES = os.path.join(ROOT, 'out', 'guide')
OUT_DOCS = os.path.join(ROOT, 'docs', 'img', 'guide')


# ---------------------------------------------------------------------------
# Scenes (built after the variant is set: they use mi types)
# ---------------------------------------------------------------------------

def look_at(mi, origin, target, up=(0, 0, 1)):
    return mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=list(up))


def sensor(mi, origin, target, fov, res, spp, width=None):
    return {'type': 'perspective', 'fov': fov, 'to_world': look_at(mi, origin, target),
            'sampler': {'type': 'independent', 'sample_count': spp},
            'film': {'type': 'hdrfilm', 'width': width or res, 'height': res,
                     'pixel_format': 'rgb', 'rfilter': {'type': 'gaussian'}}}


def small_light(centre, radius, radiance):
    return {'type': 'sphere', 'center': list(centre), 'radius': radius,
            'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': [radiance] * 3}}}


def plate_scene(mi, bsdf, res, spp, flip=False):
    """A square plate seen obliquely with the light near its mirror direction.
    flip: the plate's normal points away from the camera and the light."""
    to_world = mi.ScalarTransform4f().scale(2.0)
    if flip:
        to_world = mi.ScalarTransform4f().rotate([1, 0, 0], 180).scale(2.0)
    return {
        'type': 'scene', 'integrator': {'type': 'path', 'max_depth': 2},
        'sensor': sensor(mi, (0, -6, 4), (0, 0, 0), 40, res, spp),
        'plate': {'type': 'rectangle', 'to_world': to_world, 'bsdf': bsdf},
        'light': small_light((0.0, 6.0, 4.0), 0.12, 4000.0),
        'env': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': [0.03] * 3}},
    }


def disc_scene(mi, bsdf, res, spp, shape='disk', lamp=False):
    """scenes/cd.xml's disc (12 cm across) under a small light beyond it,
    facing the viewer; `shape`: disk or rectangle (of the disc's size).
    lamp: the light beside the camera instead (a disc under a desk lamp: the
    orders scattered back, colours for every track pitch)."""
    disc = {'type': shape, 'to_world': mi.ScalarTransform4f().translate([0, 0, 0.01]).scale(6.0),
            'bsdf': bsdf}
    if lamp:
        camera = sensor(mi, (0, -12, 9), (0, 0, 0), 40, res, spp)
        light = small_light((2.0, -13.0, 10.0), 0.15, 60000.0)
        ambient = [0.02] * 3
    else:
        camera = sensor(mi, (0, -17, 15), (0, 0.5, 0), 34, res, spp)
        light = small_light((3.0, 22.0, 20.0), 0.15, 60000.0)
        ambient = [0.3, 0.3, 0.32]
    return {
        'type': 'scene', 'integrator': {'type': 'path', 'max_depth': 2},
        'sensor': camera,
        'disc': disc,
        'hole': {'type': 'disk', 'to_world': mi.ScalarTransform4f().translate([0, 0, 0.02])
                 .scale(1.9),
                 'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': [0.02] * 3}}},
        'table': {'type': 'rectangle', 'to_world': mi.ScalarTransform4f().scale(40.0),
                  'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': [0.05] * 3}}},
        'light': light,
        'env': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': ambient}},
    }


def diffraction(**params):
    return {'type': 'diffraction', **params}


# ---------------------------------------------------------------------------
# Figures: name -> (title, columns, (exposure, percentile), tiles). exposure:
# 'shared' (one for the figure: brightness compares across tiles) or 'each'
# (every tile its own: colours show whatever the brightness); the percentile
# of the brightest channel that maps to 0.9. A tile is (label, variant,
# scene, scene arguments with the bsdf, spp[, seed]).
# ---------------------------------------------------------------------------

SIGMAS = [0.01, 0.03, 0.1, 0.3]
CORRS = [0.5, 1.0, 4.0]


def gaussian_tiles():
    tiles = []
    for t in CORRS:
        for s in SIGMAS:
            tiles.append(('sigma %g um\nT %g um' % (s, t), 'scalar_rgb', 'plate',
                          dict(bsdf=diffraction(surface='gaussian', sigma_um=s, corr_um=t)), 64))
    return tiles


CD = dict(surface='cd', tracks='concentric')
DISCS = [
    ("Stam's disc\n2.5 um", dict(CD)),
    ('CD\n1.6 um', dict(CD, period_um=1.6, height_um=0.12, width_um=0.5)),
    ('DVD\n0.74 um', dict(CD, period_um=0.74, height_um=0.1, width_um=0.32)),
    ('Blu-ray\n0.32 um', dict(CD, period_um=0.32, height_um=0.08, width_um=0.15)),
]
PLATE = dict(surface='gaussian', sigma_um=0.03, corr_um=1.0)

FIGURES = {
    'gaussian': ('Gaussian: sigma x T (each tile exposed alone)', 4, ('each', 99.0), gaussian_tiles()),
    'fractal': ('Fractal: sigma 0.05 um over 1 um, H', 4, ('each', 99.0),
                [('H %g' % h, 'scalar_rgb', 'plate',
                  dict(bsdf=diffraction(surface='fractal', sigma_um=0.05, lag_um=1.0, hurst=h)),
                  32) for h in (0.3, 0.5, 0.7, 1.0)]),
    'brushed': ('Brushed: sigma 0.25 um, twist', 3, ('shared', 99.5),
                [('isotropic\nT 2 um', 'scalar_rgb', 'plate',
                  dict(bsdf=diffraction(surface='gaussian', sigma_um=0.25, corr_um=2.0)), 32),
                 ('Tx 1.5, Ty 25 um', 'scalar_rgb', 'plate',
                  dict(bsdf=diffraction(surface='gaussian', sigma_um=0.25, corr_x_um=1.5,
                                        corr_y_um=25.0)), 32),
                 ('Tx 1.5, Ty 25 um\ntwist 90', 'scalar_rgb', 'plate',
                  dict(bsdf=diffraction(surface='gaussian', sigma_um=0.25, corr_x_um=1.5,
                                        corr_y_um=25.0, twist=90.0)), 32)]),
    'discs': ('Track pitch, lamp beside the camera', 4, ('shared', 99.5),
              [(label, 'scalar_spectral', 'disc', dict(bsdf=diffraction(**p), lamp=True), 64)
               for label, p in DISCS]),
    'coherence': ("Stam's disc: coherence_um", 3, ('shared', 98.0),
                  [('%g um' % c, 'scalar_spectral', 'disc',
                    dict(bsdf=diffraction(**CD, coherence_um=c)), 64) for c in (5.0, 50.0, 500.0)]),
    'tracks': ('tracks on a disk and a rectangle', 3, ('shared', 98.0),
               [('disk\nconcentric', 'scalar_spectral', 'disc', dict(bsdf=diffraction(**CD)), 64),
                ('rectangle\nconcentric', 'scalar_spectral', 'disc',
                 dict(bsdf=diffraction(**CD), shape='rectangle'), 64),
                ('disk\nlinear', 'scalar_spectral', 'disc',
                 dict(bsdf=diffraction(surface='cd')), 64)]),
    'rgb_spectral': ("Stam's disc: RGB or spectral", 5, ('shared', 98.0),
                     [('scalar_rgb\n16 spp, seed 1', 'scalar_rgb', 'disc',
                       dict(bsdf=diffraction(**CD)), 16, 1),
                      ('scalar_rgb\n16 spp, seed 2', 'scalar_rgb', 'disc',
                       dict(bsdf=diffraction(**CD)), 16, 2),
                      ('scalar_spectral\n16 spp, seed 1', 'scalar_spectral', 'disc',
                       dict(bsdf=diffraction(**CD)), 16, 1),
                      ('scalar_spectral\n16 spp, seed 2', 'scalar_spectral', 'disc',
                       dict(bsdf=diffraction(**CD)), 16, 2),
                      ('scalar_spectral\n256 spp', 'scalar_spectral', 'disc',
                       dict(bsdf=diffraction(**CD)), 256, 3)]),
    'one_sided': ('One-sided: front, back, twosided', 3, ('shared', 99.5),
                  [('front', 'scalar_rgb', 'plate', dict(bsdf=diffraction(**PLATE)), 32),
                   ('back', 'scalar_rgb', 'plate', dict(bsdf=diffraction(**PLATE), flip=True), 32),
                   ('back, in twosided', 'scalar_rgb', 'plate',
                    dict(bsdf={'type': 'twosided', 'bsdf': diffraction(**PLATE)}, flip=True),
                    32)]),
}

SCENES = {'plate': plate_scene, 'disc': disc_scene}
RES = {'plate': 128, 'disc': 160}


def render_tile(tile, quick):
    label, variant, scene, kwargs, spp = tile[:5]
    seed = tile[5] if len(tile) > 5 else 0
    mi = stam_mitsuba.setup(variant)
    res = RES[scene] // (2 if quick else 1)
    spp = max(4, spp // 4) if quick else spp
    d = SCENES[scene](mi, kwargs['bsdf'], res, spp,
                      **{k: v for k, v in kwargs.items() if k != 'bsdf'})
    scene = mi.load_dict(d)
    t0 = time.time()
    img = np.array(mi.render(scene, seed=seed), dtype=np.float32)[..., :3]
    dt = time.time() - t0
    if not np.all(np.isfinite(img)):
        raise RuntimeError('%s: non-finite pixels' % label)
    return img, dt


def noise(a, b, mask):
    """Seed-to-seed noise: mean |a - b| / mean (a + b) / 2 over the mask."""
    a, b = a[mask].sum(axis=-1), b[mask].sum(axis=-1)
    return float(np.abs(a - b).mean() / (0.5 * (a + b).mean()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true', help='half the resolution, a quarter '
                    'of the samples (a smoke test; writes to out/guide/ only)')
    ap.add_argument('--only', default='', help='comma-separated figure names')
    args = ap.parse_args(argv)
    names = list(FIGURES)
    if args.only:
        names = args.only.split(',')
        unknown = set(names) - set(FIGURES)
        if unknown:
            ap.error('unknown figure(s): %s (known: %s)' % (', '.join(sorted(unknown)),
                                                           ', '.join(FIGURES)))
    out_docs = os.path.join(OUT_TILES, 'quick') if args.quick else OUT_DOCS
    t_all = time.time()
    for name in names:
        title, columns, (exposure_mode, pct), tiles = FIGURES[name]
        t0 = time.time()
        done = [render_tile(t, args.quick) for t in tiles]
        imgs, times = [d[0] for d in done], [d[1] for d in done]
        # A shared exposure: the brightest tile's percentile pct to 0.9
        shared = min(stam_images.auto_exposure(img, pct) for img in imgs)
        items = []
        for k, (tile, img) in enumerate(zip(tiles, imgs)):
            png = os.path.join(OUT_TILES, name, '%02d.png' % k)
            exposure = shared if exposure_mode == 'shared' else \
                stam_images.auto_exposure(img, pct)
            stam_images.save_png(png, img, exposure)
            items.append((tile[0], png))
        tile_px = imgs[0].shape[1] * (2 if args.quick else 1)
        sheet = os.path.join(out_docs, name + '.png')
        stam_images.contact_sheet(sheet, items, columns=columns, tile=max(tile_px, 128),
                                  title=title)
        print('[guide] %-13s %2d tiles  %5.1f s  -> %s' % (name, len(tiles), time.time() - t0,
                                                           os.path.relpath(sheet, ROOT)),
              flush=True)
        if name == 'rgb_spectral':
            ref = imgs[4]
            arcs = ref.sum(axis=-1) > np.percentile(ref.sum(axis=-1), 97)
            print('[guide] seed-to-seed noise on the arcs at 16 spp: scalar_rgb %.0f%% '
                  '(%.1f s a render), scalar_spectral %.0f%% (%.1f s)' % (
                      100 * noise(imgs[0], imgs[1], arcs), 0.5 * (times[0] + times[1]),
                      100 * noise(imgs[2], imgs[3], arcs), 0.5 * (times[2] + times[3])),
                  flush=True)
    print('[guide] total %.1f s' % (time.time() - t_all))
    return 0


if __name__ == '__main__':
    sys.exit(main())
