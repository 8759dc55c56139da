"""Render time of the plugin's JIT path (issue 13) against roughconductor,
with Dr.Jit's default flags (symbolic loops and calls).

    .venv/bin/python scripts/jit_bench.py [--variant llvm_ad_rgb] [--spp 48]
        [--processes 3] [--materials gaussian,fractal,cd]
    .venv/bin/python scripts/jit_bench.py render VARIANT KIND SPP

The scene is scripts/jit_prototype.py's: 128 x 128, path tracer (max depth
6), a unit sphere filling most of the frame (fov 30 at distance 4.2) over a
diffuse floor, a rectangle light and a constant environment; the sphere
carries the material: roughconductor (Beckmann, alpha 0.1, the Beckmann
limit of the Gaussian material), or the diffraction plugin with a material of
tests/materials.json (label `plugin`). Each render runs in a fresh process,
kinds interleaved; "steady" is the fastest of 3 renders after the first
(the kernel then in Dr.Jit's cache), medians over the processes.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

PROJECT_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(PROJECT_DIR, 'scripts'))
import stam_materials  # noqa: E402
import stam_mitsuba  # noqa: E402


def scene(mi, kind, spp):
    if kind == 'roughconductor':
        bsdf = {'type': 'roughconductor', 'distribution': 'beckmann', 'alpha': 0.1}
    else:
        bsdf = {'type': 'diffraction',
                **stam_materials.plugin_params(stam_materials.by_label('plugin')[kind])}
        if kind == 'cd':
            bsdf['tracks'] = 'concentric'
    T = mi.ScalarTransform4f
    return {
        'type': 'scene',
        'integrator': {'type': 'path', 'max_depth': 6},
        'sensor': {
            'type': 'perspective', 'fov': 30,
            'to_world': T().look_at(origin=[0, 0, 4.2], target=[0, 0, 0], up=[0, 1, 0]),
            'film': {'type': 'hdrfilm', 'width': 128, 'height': 128, 'rfilter': {'type': 'box'}},
            'sampler': {'type': 'independent', 'sample_count': spp},
        },
        'sphere': {'type': 'sphere', 'bsdf': bsdf},
        'floor': {'type': 'rectangle', 'bsdf': {'type': 'diffuse'},
                  'to_world': T().translate([0, -1.0, 0]).rotate([1, 0, 0], -90).scale(10)},
        'light': {'type': 'rectangle',
                  'to_world': T().look_at(origin=[2, 3, 3], target=[0, 0, 0],
                                          up=[0, 1, 0]).scale(0.7),
                  'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': 20.0}}},
        'env': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': 0.2}},
    }


def render_once(variant, kind, spp, repeats=3):
    import numpy as np
    mi = stam_mitsuba.setup(variant, evaluated=False)
    import drjit as dr
    sc = mi.load_dict(scene(mi, kind, spp))
    times = []
    img = None
    for i in range(repeats + 1):
        t0 = time.perf_counter()
        img = mi.render(sc, seed=i)
        dr.eval(img)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    arr = np.array(img)
    return {'variant': variant, 'kind': kind, 'spp': spp,
            'symbolic': bool(dr.flag(dr.JitFlag.SymbolicLoops) and
                             dr.flag(dr.JitFlag.SymbolicCalls)),
            'first_s': times[0], 'steady_s': min(times[1:]), 'mean': float(arr.mean()),
            'finite': bool(np.all(np.isfinite(arr)))}


def bench(variant, spp, processes, materials):
    kinds = ['roughconductor'] + materials
    results = {k: [] for k in kinds}
    for _ in range(processes):
        for k in kinds:
            out = subprocess.run([sys.executable, os.path.abspath(__file__), 'render', variant, k,
                                  str(spp)], capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            results[k].append(r)
            print(json.dumps(r), flush=True)
    base = statistics.median(r['steady_s'] for r in results['roughconductor'])
    base_first = statistics.median(r['first_s'] for r in results['roughconductor'])
    for k in kinds:
        steady = statistics.median(r['steady_s'] for r in results[k])
        first = statistics.median(r['first_s'] for r in results[k])
        print('%-15s %s steady %.3f s (%.2fx roughconductor)  first render %.2f s (%.2fx)'
              % (k, variant, steady, steady / base, first, first / base_first))


if __name__ == '__main__':
    if len(sys.argv) > 1 and sys.argv[1] == 'render':
        print(json.dumps(render_once(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        sys.exit(0)
    ap = argparse.ArgumentParser()
    ap.add_argument('--variant', default='llvm_ad_rgb')
    ap.add_argument('--spp', type=int, default=48)
    ap.add_argument('--processes', type=int, default=3)
    ap.add_argument('--materials', default='gaussian,fractal,cd')
    a = ap.parse_args()
    bench(a.variant, a.spp, a.processes, a.materials.split(','))
