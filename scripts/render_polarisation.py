#!/usr/bin/env python3
"""render_polarisation.py: the picture of docs/polarisation.md. Mitsuba's
`stokes` integrator renders, in a polarised variant, a smooth aluminium
sphere and a tilted compact disc under an unpolarised point light; the
figure shows the intensity (S0), the degree of linear polarisation
(sqrt(S1^2 + S2^2) / S0) and the angle of polarisation (atan2(S2, S1) / 2)
of the reflected light, from the luminance Y of each Stokes component
(the `stokes` integrator writes each as linear sRGB; Y, a projection of the
spectrum with non-negative weights, keeps |S1|, |S2| <= S0, which a single
RGB channel of a saturated colour does not).

    .venv/bin/python scripts/render_polarisation.py [--variant llvm_ad_spectral_polarized]
        [--res 192] [--spp 64] [--out docs/img/polarisation.png]

About 10 s on two cores at the defaults (llvm_ad_spectral_polarized).

    .venv/bin/python scripts/render_polarisation.py --discs [--res 160] [--spp 32]

renders instead the compact disc twice in scalar_spectral_polarized (the
variant where rigorous gratings are polarised): with Kirchhoff's orders
(each order polarised as the Fresnel reflection at its half vector) and
with the rigorous orders (each order's Mueller matrix from the solver's
amplitudes), and plots S1 / S0 beside the intensity, where the TM-only
Wood anomalies show as bands (docs/img/polarisation_rigorous.png).
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


def scene(mi, res, spp):
    T = mi.ScalarTransform4f
    return mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'stokes', 'integrator': {'type': 'path', 'max_depth': 3}},
        'sensor': {'type': 'perspective', 'fov': 38,
                   'to_world': T().look_at(origin=[0, -5.5, 2.2], target=[0, 0, 0.55],
                                           up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': 2 * res, 'height': res,
                            'pixel_format': 'rgb'},
                   'sampler': {'type': 'independent', 'sample_count': spp}},
        # Aluminium's constant index near 650 nm: a smooth metal sphere
        'sphere': {'type': 'sphere', 'center': [-1.1, 0, 0.6], 'radius': 0.6,
                   'bsdf': {'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.03,
                            'corr_um': 1.0, 'eta': 1.2, 'k': 6.9}},
        # The paper's compact disc, tilted towards the camera
        'disc': {'type': 'disk',
                 'to_world': T().translate([1.1, 0, 0.6]).rotate([1, 0, 0], 60).scale(0.7),
                 'bsdf': {'type': 'diffraction', 'surface': 'cd'}},
        'floor': {'type': 'rectangle', 'to_world': T().scale(6),
                  'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'rgb',
                                                             'value': [0.1, 0.1, 0.1]}}},
        'light': {'type': 'point', 'position': [0.5, -3, 4],
                  'intensity': {'type': 'spectrum', 'value': 60.0}},
        'env': {'type': 'constant', 'radiance': {'type': 'spectrum', 'value': 0.05}},
    })


def disc_scene(mi, res, spp, orders):
    T = mi.ScalarTransform4f
    return mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'stokes', 'integrator': {'type': 'direct'}},
        'sensor': {'type': 'perspective', 'fov': 32,
                   'to_world': T().look_at(origin=[0, -3.2, 2.4], target=[0, 0, 0], up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': res, 'height': res,
                            'pixel_format': 'rgb'},
                   'sampler': {'type': 'independent', 'sample_count': spp}},
        'disc': {'type': 'disk', 'bsdf': {'type': 'diffraction', 'surface': 'cd',
                                          'orders': orders}},
        # A long strip light behind the disc, facing it: each track's orders
        # sweep through it
        'light': {'type': 'rectangle',
                  'to_world': T().look_at(origin=[0, 2.6, 2.0], target=[0, 0, 0], up=[0, 0, 1])
                  @ T().scale([2.5, 0.08, 1]),
                  'emitter': {'type': 'area', 'radiance': {'type': 'spectrum', 'value': 30.0}}},
    })


def stokes_luminance(img):
    return img[..., 3:].reshape(img.shape[:2] + (4, 3)) @ np.array([0.2126, 0.7152, 0.0722])


def discs(args):
    variant = 'scalar_spectral_polarized'
    mi = stam_mitsuba.setup(variant)
    rows = []
    for orders in ('kirchhoff', 'rigorous'):
        t = time.perf_counter()
        img = np.array(mi.render(disc_scene(mi, args.res, args.spp, orders)), dtype=np.float64)
        s = stokes_luminance(img)
        lit = s[..., 0] > 1e-3 * np.percentile(s[..., 0], 99)
        s1 = np.where(lit, s[..., 1] / np.maximum(s[..., 0], 1e-30), np.nan)
        dolp = np.where(lit, np.hypot(s[..., 1], s[..., 2]) / np.maximum(s[..., 0], 1e-30), np.nan)
        print('[render_polarisation] %s disc, %s %dx%d, %d spp: %.1f s; DoLP median %.3f, '
              'p99 %.3f; S1/S0 range %.3f..%.3f'
              % (orders, variant, args.res, args.res, args.spp, time.perf_counter() - t,
                 np.nanmedian(dolp), np.nanpercentile(dolp, 99), np.nanmin(s1), np.nanmax(s1)))
        rows.append((orders, img, s1, dolp))

    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 3, figsize=(12, 8))
    scale = max(np.percentile(rows[1][1][..., :3], 99.5), 1e-12)
    lim = max(0.05, max(float(np.nanpercentile(np.abs(r[2]), 99)) for r in rows))
    for (orders, img, s1, dolp), ax in zip(rows, axes):
        ax[0].imshow(np.clip(img[..., :3] / scale, 0, 1) ** (1 / 2.2))
        ax[0].set_title('%s orders: intensity' % orders)
        im = ax[1].imshow(s1, cmap='RdBu_r', vmin=-lim, vmax=lim)
        ax[1].set_title('S1 / S0 (+: along the first basis axis)')
        fig.colorbar(im, ax=ax[1], fraction=0.04)
        im = ax[2].imshow(dolp, cmap='magma', vmin=0, vmax=lim)
        ax[2].set_title('degree of linear polarisation')
        fig.colorbar(im, ax=ax[2], fraction=0.04)
        for a in ax:
            a.axis('off')
    fig.suptitle('compact disc in %s, `stokes` integrator: Kirchhoff orders (top) and '
                 'rigorous orders (bottom)' % variant, fontsize=10)
    out = os.path.join(ROOT, 'docs', 'img', 'polarisation_rigorous.png')
    fig.savefig(out, dpi=80, bbox_inches='tight')
    print('[render_polarisation] wrote %s' % out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--variant', default='llvm_ad_spectral_polarized')
    ap.add_argument('--res', type=int, default=192)
    ap.add_argument('--spp', type=int, default=64)
    ap.add_argument('--out', default=os.path.join(ROOT, 'docs', 'img', 'polarisation.png'))
    ap.add_argument('--discs', action='store_true',
                    help='the compact disc with Kirchhoff and rigorous orders (see above)')
    args = ap.parse_args()
    if args.discs:
        return discs(args)

    mi = stam_mitsuba.setup(args.variant)
    t = time.perf_counter()
    img = np.array(mi.render(scene(mi, args.res, args.spp)), dtype=np.float64)
    print('[render_polarisation] %s %dx%d, %d spp: %.1f s'
          % (args.variant, 2 * args.res, args.res, args.spp, time.perf_counter() - t))
    # The stokes integrator's channels: the image (RGB), then S0..S3 (RGB
    # each), each component's luminance
    s = stokes_luminance(img)
    s0 = s[..., 0]
    lit = s0 > 1e-3 * np.percentile(s0, 99)
    dolp = np.where(lit, np.hypot(s[..., 1], s[..., 2]) / np.maximum(s0, 1e-30), np.nan)
    aop = np.where(lit & (dolp > 0.01), 0.5 * np.degrees(np.arctan2(s[..., 2], s[..., 1])), np.nan)
    print('[render_polarisation] degree of linear polarisation: median %.3f, max %.3f'
          % (np.nanmedian(dolp), np.nanmax(dolp)))

    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rgb = img[..., :3] / max(np.percentile(img[..., :3], 99.5), 1e-12)
    rgb = np.clip(rgb, 0, 1) ** (1 / 2.2)
    fig, axes = plt.subplots(1, 3, figsize=(15, 2.9))
    axes[0].imshow(rgb)
    axes[0].set_title('intensity (S0, tone-mapped)')
    im = axes[1].imshow(dolp, cmap='magma', vmin=0, vmax=max(0.05, float(np.nanmax(dolp))))
    axes[1].set_title('degree of linear polarisation')
    fig.colorbar(im, ax=axes[1], fraction=0.025)
    im = axes[2].imshow(aop, cmap='twilight', vmin=-90, vmax=90)
    axes[2].set_title('angle of polarisation (deg)')
    fig.colorbar(im, ax=axes[2], fraction=0.025)
    for a in axes:
        a.axis('off')
    fig.suptitle('diffraction BSDF in %s: a smooth aluminium sphere (left) and the compact '
                 'disc (right), `stokes` integrator' % args.variant, fontsize=10)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    fig.savefig(args.out, dpi=90, bbox_inches='tight')
    print('[render_polarisation] wrote %s' % args.out)


if __name__ == '__main__':
    main()
