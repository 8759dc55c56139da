#!/usr/bin/env python3
"""Inverse rendering with the `diffraction` BSDF (issue 14, docs/inverse.md):
recover material parameters from target images rendered with known ones.

    .venv/bin/python scripts/inverse_rendering.py [--case gaussian|grating] [--steps 200]
        [--variant V] [--out out/inverse]

Case `grating` (llvm_ad_spectral): the period of a sine grating from 30%
high, under a wide strip light beside the mirror direction, so that the
plate shows the first order's rainbow, whose place follows the period.

Case `gaussian`: the RMS height sigma_um and the correlation length corr_um
of a Gaussian surface, each started 30% off (sigma 30% high, corr 30% low).
The surface is in the wave regime (sigma 0.05 um: g = (k sigma (cos_i +
cos_o))^2 ~ 1), where the diffuse lobe's strength tells sigma and its width
corr; rougher surfaces reach the geometric limit, where only the slope sigma
/ corr shows (the optimiser then slides along that valley). The scene is a
plate seen at an angle under three point lights, so that the image spans
the lobe. Adam on the logarithms of the parameters, loss = the mean
squared difference to the target image; the gradients come from Mitsuba's
`prb` integrator through the plugin's JIT path (Dr.Jit's default flags).
Writes <out>/<case>_convergence.png (loss and parameter errors against the
step), <out>/<case>_images.png (before, target, after) and prints each
parameter's final error; exits 1 if one is above --tolerance (1%).
"""

import argparse
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import stam_mitsuba  # noqa: E402

CASES = {
    # truth, start (30% off), the material's other parameters, the variant
    'gaussian': {
        'truth': {'sigma_um': 0.05, 'corr_um': 2.0},
        'start': {'sigma_um': 0.065, 'corr_um': 1.4},
        'fixed': {'surface': 'gaussian', 'fresnel': 0.9},
        'variant': 'llvm_ad_rgb',
    },
    # The grating's period, in llvm_ad_spectral: the RGB programs read it
    # too (docs/inverse.md), but the spectral kernel is smaller and the loss
    # has no gamut map bending it.
    'grating': {
        'truth': {'period_um': 1.2},
        'start': {'period_um': 1.56},
        'fixed': {'surface': 'periodic', 'profile': 'sine', 'height_um': 0.2,
                  'coherence_um': 4.0, 'fresnel': 0.9},
        'variant': 'llvm_ad_spectral',
        'lights': 'strip',
    },
}


def scene_dict(mi, bsdf, res, spp, lights='points'):
    T = mi.ScalarTransform4f
    if lights == 'points':
        lights = {'light%d' % i: {'type': 'point', 'position': p,
                                  'intensity': {'type': 'spectrum', 'value': w}}
                  for i, (p, w) in enumerate([([0.0, 1.8, 1.9], 6.0), ([0.9, 1.2, 2.6], 6.0),
                                              ([-1.0, 1.5, 1.6], 4.0)])}
    else:
        # A wide strip light low on the side the grooves disperse towards:
        # the plate shows a continuous rainbow whose place follows the period
        lights = {'strip': {'type': 'rectangle',
                            'to_world': T().look_at(origin=[1.3, 2.0, 1.8], target=[0, 0, 0],
                                                    up=[0, 0, 1]).scale([1.0, 0.3, 1]),
                            'emitter': {'type': 'area',
                                        'radiance': {'type': 'spectrum', 'value': 4.0}}}}
    return {
        'type': 'scene',
        'integrator': {'type': 'prb', 'max_depth': 2},
        'sensor': {'type': 'perspective', 'fov': 45,
                   'to_world': T().look_at(origin=[0, -2.2, 2.0], target=[0, 0.2, 0],
                                           up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': res, 'height': res,
                            'rfilter': {'type': 'box'}},
                   'sampler': {'type': 'independent', 'sample_count': spp}},
        'plate': {'type': 'rectangle', 'to_world': T().scale(1.5),
                  'bsdf': {'type': 'diffraction', **bsdf}},
        **lights,
    }


SEED = 1


def optimise(case, steps, variant=None, res=48, spp=8, lr=0.05, log=print):
    """Returns {'truth', 'start', 'history': [(loss, {key: value})], 'images':
    (before, target, after), 'seconds'}; variant None: the case's."""
    mi = stam_mitsuba.setup(variant or CASES[case]['variant'])
    import drjit as dr
    c = CASES[case]
    keys = list(c['truth'])
    scene = mi.load_dict(scene_dict(mi, {**c['fixed'], **c['truth']}, res, spp,
                                    c.get('lights', 'points')))
    # The target and every iterate render the same pixel samples (one seed):
    # their difference is the parameters' alone, so the loss reaches 0 at the
    # truth; the gradient passes draw their own samples (seed_grad).
    target = mi.render(scene, seed=SEED)
    dr.eval(target)
    params = mi.traverse(scene)
    full = {k: 'plate.bsdf.' + k for k in keys}

    def set_values(values):
        for k in keys:
            params[full[k]] = values[k]
        params.update()

    set_values({k: mi.Float(v) for k, v in c['start'].items()})
    before = mi.render(scene, seed=0)
    opt = mi.ad.Adam(lr=lr)
    for k in keys:
        opt[k] = mi.Float(math.log(c['start'][k]))
    history = []
    t0 = time.time()
    for it in range(steps):
        # learning rate decaying to a tenth over the run
        opt.set_learning_rate(lr * 0.1 ** (it / max(steps - 1, 1)))
        set_values({k: dr.exp(opt[k]) for k in keys})
        img = mi.render(scene, params=params, seed=SEED, seed_grad=SEED + 1 + it)
        loss = dr.mean(dr.square(img - target), axis=None)
        dr.backward(loss)
        opt.step()
        values = {k: float(math.exp(opt[k][0])) for k in keys}
        history.append((float(np.array(loss).ravel()[0]), values))
        if it % 20 == 0 or it == steps - 1:
            log('[inverse] %s step %3d: loss %.3e, %s' % (
                case, it, history[-1][0],
                ', '.join('%s %.4f (%+.2f%%)' % (k, v, 100 * (v / c['truth'][k] - 1))
                          for k, v in values.items())))
    set_values({k: mi.Float(v) for k, v in history[-1][1].items()})
    after = mi.render(scene, seed=0)
    to_np = lambda x: np.array(x, dtype=np.float64)  # noqa: E731
    return {'truth': c['truth'], 'start': c['start'], 'history': history,
            'images': (to_np(before), to_np(target), to_np(after)),
            'seconds': time.time() - t0}


def write_pictures(case, result, out):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import stam_images
    os.makedirs(out, exist_ok=True)
    hist = result['history']
    steps = np.arange(len(hist))
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    a.semilogy(steps, [h[0] for h in hist])
    a.set_xlabel('step')
    a.set_ylabel('loss (mean squared error)')
    for k, truth in result['truth'].items():
        b.plot(steps, [100 * (h[1][k] / truth - 1) for h in hist], label=k)
    b.axhline(1, color='grey', lw=0.5, ls='--')
    b.axhline(-1, color='grey', lw=0.5, ls='--')
    b.set_xlabel('step')
    b.set_ylabel('error against the truth (%)')
    b.legend()
    fig.suptitle('diffraction: %s parameters from a target image' % case)
    fig.tight_layout()
    fig.savefig(os.path.join(out, '%s_convergence.png' % case), dpi=100)
    plt.close(fig)
    before, target, after = result['images']
    exposure = stam_images.auto_exposure(target)
    items = []
    for img, name, label in ((before, 'start', 'start (30% off)'), (target, 'target', 'target'),
                             (after, 'recovered', 'recovered')):
        path = os.path.join(out, '%s_%s.png' % (case, name))
        big = np.repeat(np.repeat(img, 4, axis=0), 4, axis=1)   # 4x, nearest
        stam_images.save_png(path, big, exposure)
        items.append((label, path))
    stam_images.contact_sheet(os.path.join(out, '%s_images.png' % case), items, columns=3,
                              tile=192)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--case', default='gaussian', choices=sorted(CASES))
    ap.add_argument('--steps', type=int, default=200)
    ap.add_argument('--variant', default=None, help="default: the case's (gaussian: "
                    "llvm_ad_rgb, grating: llvm_ad_spectral)")
    ap.add_argument('--tolerance', type=float, default=0.01)
    ap.add_argument('--out', default=os.path.join(os.path.dirname(HERE), 'out', 'inverse'))
    args = ap.parse_args(argv)
    result = optimise(args.case, args.steps, args.variant)
    write_pictures(args.case, result, args.out)
    final = result['history'][-1][1]
    errors = {k: final[k] / t - 1 for k, t in result['truth'].items()}
    print('[inverse] %s: %d steps in %.0f s; %s' % (
        args.case, args.steps, result['seconds'],
        ', '.join('%s %.4f (truth %.4f, error %+.2f%%)'
                  % (k, final[k], result['truth'][k], 100 * e) for k, e in errors.items())))
    print('[inverse] wrote %s_convergence.png and %s_images.png in %s'
          % (args.case, args.case, args.out))
    return 0 if all(abs(e) <= args.tolerance for e in errors.values()) else 1


if __name__ == '__main__':
    sys.exit(main())
