#!/usr/bin/env python3
"""Render time of two small scenes with the `diffraction` BSDF against the
same scenes with Mitsuba's `roughconductor`, in one process per round of
materials (repeated in fresh processes; the median is the figure).

    .venv/bin/python scripts/bench_scenes.py [--variants llvm_ad_rgb,scalar_rgb]
        [--processes 3] [--repeats 3] [--scenes small,cbox]

The scenes (issue 46):
- small: 128 x 128, 48 spp, path tracing to depth 3, the material on a disk
  and a sphere that fill the frame, under a point light and a constant
  environment; warm kernels (each scene rendered once untimed), the fastest
  of `repeats` renders, the materials interleaved in one process.
- cbox: Mitsuba's Cornell box (mi.cornell_box(), 256 x 256, 64 spp, depth 8)
  with one small sphere of the material on its floor, everything else
  diffuse: a scene where the material is a small part of the frame. Its
  total is what a user waits for in a fresh process: loading the scene
  (the material's tables), the first render (tracing, and compiling or
  loading the kernel from Dr.Jit's cache) and a second render.

The diffraction materials are the rough Gaussian whose large-g limit is
that roughconductor (alpha = 2 sigma / T), and the compact disc.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render  # noqa: E402
import stam_mitsuba  # noqa: E402

# bench_render's baseline and materials, under short names.
MATERIALS = {short: bench_render.MATERIALS[name] for short, name in (
    ('roughconductor', 'roughconductor (baseline)'),
    ('gaussian (rough)', 'diffraction gaussian (rough)'),
    ('cd', 'diffraction cd'))}
JSON_TAG = '@@bench_scenes '


def small_scene(mi, bsdf):
    """A disk and a sphere filling a 128 x 128 frame (the disk's polar uv
    give the compact disc its concentric tracks)."""
    T = mi.ScalarTransform4f
    return mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'path', 'max_depth': 3},
        'sensor': {'type': 'perspective', 'fov': 40,
                   'to_world': T().look_at(origin=[0, -3.2, 2.4], target=[0, 0, 0.3],
                                           up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': 128, 'height': 128},
                   'sampler': {'type': 'independent', 'sample_count': 48}},
        'disk': {'type': 'disk', 'to_world': T().scale([1.6, 1.6, 1]), 'bsdf': bsdf},
        'sphere': {'type': 'sphere', 'center': [0.55, 0.2, 0.6], 'radius': 0.6, 'bsdf': bsdf},
        'light': {'type': 'point', 'position': [2, -2, 4],
                  'intensity': {'type': 'spectrum', 'value': 40.0}},
        'env': {'type': 'constant', 'radiance': {'type': 'spectrum', 'value': 0.3}},
    })


def cbox_scene(mi, bsdf):
    """Mitsuba's Cornell box, its two boxes replaced by one small sphere of
    the material on the floor."""
    d = mi.cornell_box()
    del d['small-box'], d['large-box']
    d['sensor']['sampler']['sample_count'] = 64
    d['sphere'] = {'type': 'sphere', 'center': [0.3, -0.7, 0.2], 'radius': 0.3, 'bsdf': bsdf}
    return mi.load_dict(d)


def time_cbox(mi, name):
    """(load, first render, second render) seconds of the Cornell box with
    one material, in this process (fresh: see `run_processes`)."""
    t0 = time.perf_counter()
    s = cbox_scene(mi, MATERIALS[name])
    t1 = time.perf_counter()
    bench_render.rendered(mi, s, 0)
    t2 = time.perf_counter()
    bench_render.rendered(mi, s, 1)
    t3 = time.perf_counter()
    return t1 - t0, t2 - t1, t3 - t2


def child(args):
    mi = stam_mitsuba.setup(args.variant)
    if args.scene == 'small':
        # Warm kernels, the materials interleaved (bench_render's rounds)
        out = bench_render.time_renders(mi, MATERIALS, lambda bsdf: small_scene(mi, bsdf),
                                        args.repeats)
    else:
        out = time_cbox(mi, args.material)
    print(JSON_TAG + json.dumps(out), flush=True)


def run_child(**kw):
    cmd = [sys.executable, os.path.abspath(__file__), '--child']
    for k, v in kw.items():
        cmd += ['--' + k, str(v)]
    out = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True).stdout
    return json.loads(next(line[len(JSON_TAG):] for line in out.splitlines()
                           if line.startswith(JSON_TAG)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--variants', default='llvm_ad_rgb,scalar_rgb')
    ap.add_argument('--scenes', default='small,cbox')
    ap.add_argument('--processes', type=int, default=3)
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--variant', help=argparse.SUPPRESS)
    ap.add_argument('--scene', help=argparse.SUPPRESS)
    ap.add_argument('--material', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args)
    for variant in args.variants.split(','):
        if 'small' in args.scenes.split(','):
            runs = [run_child(variant=variant, scene='small', repeats=args.repeats)
                    for _ in range(args.processes)]
            base = [r['roughconductor'] for r in runs]
            for name in MATERIALS:
                ratios = [r[name] / b for r, b in zip(runs, base)]
                print('[bench_scenes] %-12s small  %-18s %6.3f s  %5.2fx  (%.2f-%.2fx)'
                      % (variant, name, statistics.median(r[name] for r in runs),
                         statistics.median(ratios), min(ratios), max(ratios)), flush=True)
        if 'cbox' in args.scenes.split(',') and not variant.startswith('scalar'):
            # Fresh processes, the materials alternating process by process.
            times = {name: [] for name in MATERIALS}
            for _ in range(args.processes):
                for name in MATERIALS:
                    times[name].append(run_child(variant=variant, scene='cbox', material=name))
            base = [sum(t) for t in times['roughconductor']]
            for name, ts in times.items():
                med = [statistics.median(t[k] for t in ts) for k in range(3)]
                ratios = [sum(t) / b for t, b in zip(ts, base)]
                print('[bench_scenes] %-12s cbox   %-18s load %5.2f s  first %5.2f s  second '
                      '%5.2f s  total %5.2f s  %5.2fx  (%.2f-%.2fx)'
                      % (variant, name, med[0], med[1], med[2],
                         statistics.median(sum(t) for t in ts), statistics.median(ratios),
                         min(ratios), max(ratios)), flush=True)


if __name__ == '__main__':
    main()
