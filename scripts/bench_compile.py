#!/usr/bin/env python3
"""Compile cost of diffraction materials in a JIT variant: the first render
(tracing, compiling: an empty Dr.Jit kernel cache), a second one (Mitsuba
3.9.1 traces the second render of a scene to another kernel than the first,
for its own BSDFs as for ours: two compilations) and a warm third of a
scene with N distinct materials of one family on N spheres, against the same
scene with N distinct `roughconductor`s; and a scene without any diffraction
material while N of them are merely alive in the process (Mitsuba's
symbolic calls trace every BSDF alive), against the plugin not imported.
Each row runs in a fresh process with its own empty kernel cache.

    .venv/bin/python scripts/bench_compile.py [--variant llvm_ad_rgb]
        [--counts 1,2,4,8,20] [--families gaussian,cd_twist,sine_period]
        [--write docs/compile_cost.md]

Families: `gaussian` (sigma_um and corr_um differ), `cd_twist` (compact discs
turned by different twists), `sine_period` (sine gratings of different
periods), `roughconductor` (alpha differs: the baseline).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def material(family, i):
    if family == 'roughconductor':
        return {'type': 'roughconductor', 'distribution': 'beckmann', 'alpha': 0.1 + 0.02 * i}
    if family == 'gaussian':
        return {'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.05 + 0.01 * i,
                'corr_um': 1.5 + 0.1 * i}
    if family == 'cd_twist':
        return {'type': 'diffraction', 'surface': 'cd', 'twist': 7.0 * i}
    if family == 'sine_period':
        return {'type': 'diffraction', 'surface': 'periodic', 'profile': 'sine',
                'period_um': 1.2 + 0.15 * i, 'height_um': 0.15, 'coherence_um': 10.0}
    raise ValueError(family)


def child(args):
    """One measurement in this process: prints a JSON line."""
    sys.path.insert(0, HERE)
    if args.mode != 'no_plugin':
        import stam_mitsuba
        stam_mitsuba.setup(args.variant)
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    T = mi.ScalarTransform4f
    d = {'type': 'scene', 'integrator': {'type': 'path', 'max_depth': 3},
         'sensor': {'type': 'perspective', 'fov': 40,
                    'to_world': T().look_at(origin=[0, -6, 4], target=[0, 0, 0], up=[0, 0, 1]),
                    'film': {'type': 'hdrfilm', 'width': 64, 'height': 64},
                    'sampler': {'type': 'independent', 'sample_count': 4}},
         'floor': {'type': 'rectangle', 'to_world': T().scale(5), 'bsdf': {'type': 'diffuse'}},
         'light': {'type': 'point', 'position': [1, -2, 5],
                   'intensity': {'type': 'spectrum', 'value': 40.0}}}
    alive = []
    t0 = time.time()
    if args.mode == 'in_scene':
        for i in range(args.count):
            x = -3.0 + 6.0 * (i + 0.5) / args.count
            d['s%d' % i] = {'type': 'sphere', 'radius': min(0.4, 2.5 / args.count),
                            'center': [x, 0, 0.4], 'bsdf': material(args.family, i)}
    elif args.mode == 'alive':
        alive = [mi.load_dict(material(args.family, i), parallel=False)
                 for i in range(args.count)]
    scene = mi.load_dict(d, parallel=False)
    t_load = time.time() - t0
    times = []
    for seed in range(3):
        t = time.time()
        dr.eval(mi.render(scene, seed=seed))
        dr.sync_thread()
        times.append(time.time() - t)
    print(json.dumps({'load': t_load, 'first': times[0], 'second': times[1],
                      'warm': times[2], 'alive': len(alive)}))


def measure(args, family, count, mode):
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, DRJIT_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, os.path.abspath(__file__), '--child',
                              '--variant', args.variant, '--family', family,
                              '--count', str(count), '--mode', mode],
                             env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--variant', default='llvm_ad_rgb')
    ap.add_argument('--counts', default='1,2,4,8,20')
    ap.add_argument('--families', default='gaussian,cd_twist,sine_period')
    ap.add_argument('--write', default=None)
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--family', help=argparse.SUPPRESS)
    ap.add_argument('--count', type=int, help=argparse.SUPPRESS)
    ap.add_argument('--mode', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args)
    counts = [int(c) for c in args.counts.split(',')]
    lines = ['| family | N | load (s) | first render (s) | second render (s) | warm (s) |',
             '|---|---|---|---|---|---|']
    for family in ['roughconductor'] + args.families.split(','):
        for n in counts:
            r = measure(args, family, n, 'in_scene')
            lines.append('| %s | %d | %.2f | %.2f | %.2f | %.3f |' % (
                family, n, r['load'], r['first'], r['second'], r['warm']))
            print(lines[-1], flush=True)
    lines += ['', '| scene without diffraction materials | alive | first render (s) |',
              '|---|---|---|']
    counts_alive = [c for c in counts if c <= 8]
    r = measure(args, 'roughconductor', 0, 'no_plugin')
    lines.append('| plugin not imported | 0 | %.2f |' % r['first'])
    print(lines[-1], flush=True)
    for family in args.families.split(','):
        for n in [0] + counts_alive:
            r = measure(args, family, n, 'alive')
            lines.append('| %s | %d | %.2f |' % (family, n, r['first']))
            print(lines[-1], flush=True)
    if args.write:
        with open(args.write, 'w') as f:
            f.write('# Compile cost of diffraction materials (%s)\n\n' % args.variant)
            f.write('Generated by `scripts/bench_compile.py --write %s`: each row a fresh '
                    'process with an empty Dr.Jit kernel cache; 64x64, 4 spp, path tracing '
                    'to depth 3, N spheres with N distinct materials of the family on a '
                    'diffuse floor.\n\n' % args.write)
            f.write('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
