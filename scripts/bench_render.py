#!/usr/bin/env python3
"""Render time of one fixed scene with the `diffraction` BSDF against the same
scene with Mitsuba's own `roughconductor` (Beckmann), same spp, same variant,
in one process (repeated in a few fresh processes, whose median is the
figure); prints the ratios and writes docs/plugin_speed.md.

    .venv/bin/python scripts/bench_render.py [--spp 64] [--size 128] [--repeats 5]
        [--processes 3] [--only heightmap,cd] [--write docs/plugin_speed.md]

The scene: a sphere filling most of the frame (its disc covers 66% of the
image) on a plane under a point light and a constant environment, path tracing
to depth 4, so the BSDF is sampled, evaluated and its pdf queried as in a real
render. The diffraction material is the rough-Gaussian one whose large-g limit
is that roughconductor (alpha = 2 sigma / T), so both scenes do the same light
transport; each render is repeated and the fastest kept. Every diffraction
material is timed with the default energy-conserving formula and again with
Stam's ("energy": "stam").

JIT variants (llvm_ad_*) run with Dr.Jit's default flags (symbolic loops and
calls: Mitsuba's default mode), the plugin executing the core's programs
(docs/jit.md); the first render of each scene (tracing, compiling or loading
the kernel from Dr.Jit's cache) is not timed.
"""
import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import stam_mitsuba  # noqa: E402

SIGMA_UM, CORR_UM = 0.5, 4.0
MATERIALS = {
    'roughconductor (baseline)': {'type': 'roughconductor', 'distribution': 'beckmann',
                                  'alpha': 2 * SIGMA_UM / CORR_UM, 'material': 'Al'},
    'diffraction gaussian (rough)': {'type': 'diffraction', 'surface': 'gaussian',
                                     'sigma_um': SIGMA_UM, 'corr_um': CORR_UM},
    'diffraction gaussian (smooth)': {'type': 'diffraction', 'surface': 'gaussian',
                                      'sigma_um': 0.05, 'corr_um': 2.0},
    'diffraction fractal': {'type': 'diffraction', 'surface': 'fractal', 'hurst': 0.7,
                            'sigma_um': 0.1, 'lag_um': 1.0},
    'diffraction cd': {'type': 'diffraction', 'surface': 'cd'},
}
# The same materials with Stam's formula ("energy": "stam"): the rows above
# are the default ("conserving", docs/energy.md), so the table shows what its
# energy table costs, in the same process and rounds.
MATERIALS.update({name + ', Stam\'s formula': dict(bsdf, energy='stam')
                  for name, bsdf in list(MATERIALS.items()) if bsdf['type'] == 'diffraction'})
# The disc with rigorous orders (docs/rigorous.md; energy-exact by itself, no
# "energy").
MATERIALS['diffraction cd, rigorous orders'] = {'type': 'diffraction', 'surface': 'cd',
                                                 'orders': 'rigorous'}
# A height map (docs/heightmap.md): the demo's Gaussian-correlated map
# (`make heightmaps`), sigma 0.05 um, T 1 um.
HEIGHTMAP = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                         'scenes', 'heightmaps', 'gaussian.npy')
MATERIALS['diffraction heightmap (gaussian map)'] = {'type': 'diffraction',
                                                     'surface': 'heightmap',
                                                     'file': HEIGHTMAP, 'pixel_um': 0.08}
BASELINE = 'roughconductor (baseline)'


def scene(mi, bsdf, size, spp):
    return mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'path', 'max_depth': 4},
        # The unit sphere seen from 4.2 away: an angular diameter of 27.5
        # degrees in a 30 degree field, 66% of the frame.
        'sensor': {'type': 'perspective', 'fov': 30,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -3.8, 2.79],
                                                              target=[0, 0, 1], up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': size, 'height': size},
                   'sampler': {'type': 'independent', 'sample_count': spp}},
        'sphere': {'type': 'sphere', 'center': [0, 0, 1], 'radius': 1, 'bsdf': bsdf},
        'floor': {'type': 'rectangle', 'to_world': mi.ScalarTransform4f().scale([4, 4, 1]),
                  'bsdf': {'type': 'diffuse'}},
        'light': {'type': 'point', 'position': [2, -2, 4],
                  'intensity': {'type': 'spectrum', 'value': 40.0}},
        'env': {'type': 'constant', 'radiance': {'type': 'spectrum', 'value': 0.3}},
    })


def rendered(mi, s, seed, spp=0):
    """A render with its kernels finished: in a JIT variant mi.render
    returns once its kernels are queued (it waits for the previous
    render's), so an unsynchronised time is that of whatever ran before.
    spp 0: the scene's sampler's."""
    import drjit as dr
    img = mi.render(s, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()


def time_renders(mi, materials, make_scene, repeats):
    """Fastest of `repeats` renders per material. The rounds are interleaved
    (every material once per round), so that a slow spell of the shared
    machine hits all of them alike instead of one material's renders.

    Only one scene exists at a time: in JIT variants a symbolic virtual call
    traces every BSDF registered in the variant, so with all the scenes alive
    each kernel would carry every material's code (the baseline's too: it
    measured 3.6x slower that way). Each round builds the scene afresh and
    renders it once untimed (tables, tracing, the kernel from Dr.Jit's
    cache), then times one render. make_scene(bsdf): the scene of a
    material."""
    best = {name: float('inf') for name in materials}
    for r in range(repeats):
        for name, bsdf in materials.items():
            s = make_scene(bsdf)
            rendered(mi, s, 0)
            t = time.perf_counter()
            rendered(mi, s, r + 1)
            best[name] = min(best[name], time.perf_counter() - t)
            del s
            gc.collect()
    return best


def run_one(args):
    """One process: every variant's interleaved rounds. Returns rows
    (variant, material, fastest seconds, ratio to the baseline)."""
    rows = []
    for variant in args.variants.split(','):
        # JIT variants in Mitsuba's default (symbolic) mode
        mi = stam_mitsuba.setup(variant)
        materials = {name: bsdf for name, bsdf in MATERIALS.items()
                     if name == BASELINE or not args.only
                     or any(o in name for o in args.only.split(','))}
        print('[bench_render] %s: %d interleaved rounds of %d renders...'
              % (variant, args.repeats, len(materials)), flush=True)
        best = time_renders(mi, materials, lambda bsdf: scene(mi, bsdf, args.size, args.spp),
                            args.repeats)
        base = best[BASELINE]
        for name, t in best.items():
            rows.append((variant, name, t, t / base))
            print('[bench_render] %-16s %-46s %7.3f s  %5.2fx' % (variant, name, t, t / base),
                  flush=True)
    return rows


def run_processes(args):
    """`args.processes` runs of `run_one`, each in a fresh process (a slow
    spell of the shared machine can last a whole process: the median over
    processes is the figure, the range shows the spread). Returns rows
    (variant, material, median seconds, median ratio, lowest, highest)."""
    child = [sys.executable, os.path.abspath(__file__), '--child', '--spp', str(args.spp),
             '--size', str(args.size), '--repeats', str(args.repeats),
             '--variants', args.variants] + (['--only', args.only] if args.only else [])
    runs = []
    for k in range(args.processes):
        print('[bench_render] process %d of %d' % (k + 1, args.processes), flush=True)
        out = subprocess.run(child, check=True, stdout=subprocess.PIPE, text=True).stdout
        for line in out.splitlines():
            if line.startswith(JSON_TAG):
                runs.append(json.loads(line[len(JSON_TAG):]))
            else:
                print(line, flush=True)
    rows = []
    for i, (variant, name, _, _) in enumerate(runs[0]):
        times = [r[i][2] for r in runs]
        ratios = [r[i][3] for r in runs]
        rows.append((variant, name, statistics.median(times), statistics.median(ratios),
                     min(ratios), max(ratios)))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--spp', type=int, default=64)
    ap.add_argument('--size', type=int, default=128)
    ap.add_argument('--repeats', type=int, default=5)
    ap.add_argument('--processes', type=int, default=3,
                    help='independent processes; the table gives the median ratio and the range')
    ap.add_argument('--variants',
                    default='scalar_rgb,scalar_spectral,llvm_ad_rgb,llvm_ad_spectral')
    ap.add_argument('--only', default='',
                    help='comma-separated parts of material names to time (the baseline always)')
    ap.add_argument('--write', default=None, help='markdown file to write the table to')
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()

    if args.child:
        print(JSON_TAG + json.dumps(run_one(args)), flush=True)
        return
    if args.processes > 1:
        rows = run_processes(args)
    else:  # one process: its ratio is the median and the whole range
        rows = [r + (r[3], r[3]) for r in run_one(args)]
    print('[bench_render] median over %d process(es) (range):' % max(args.processes, 1))
    for r in rows:
        print('[bench_render] %-16s %-46s %7.3f s  %5.2fx  (%.2f-%.2fx)' % r, flush=True)

    lines = [MARK,
             'Generated by `scripts/bench_render.py --spp %d --size %d --repeats %d --processes %d` '
             '(%s): in each of %d processes, the fastest of %d interleaved renders per material; '
             'the table gives the median over the processes and the range of the ratio. Path '
             'tracing to depth 4 of a sphere filling 66%% of the frame on a diffuse floor; ratio '
             'to the same scene with `roughconductor` (Beckmann, alpha = 2 sigma / T = %.2f, Al) '
             'in the same variant and mode (JIT variants: Dr.Jit\'s default flags); each '
             'diffraction material with the default `"energy": "conserving"` and with Stam\'s '
             'formula; the disc with rigorous orders. Goals: at most 1.5x in '
             'scalar variants, 2x in JIT variants.'
             % (args.spp, args.size, args.repeats, args.processes, time.strftime('%Y-%m-%d'),
                max(args.processes, 1), args.repeats, 2 * SIGMA_UM / CORR_UM), '',
             '| variant | material | seconds (median) | ratio (median) | ratio range |',
             '|---|---|---|---|---|']
    lines += ['| %s | %s | %.3f | %.2fx | %.2f-%.2fx |' % r for r in rows]
    lines.append(MARK)
    table = '\n'.join(lines)
    if args.write:
        write_table(args.write, table)
        print('[bench_render] wrote', args.write)


JSON_TAG = '@@bench_render '
MARK = '<!-- render-table -->'


def write_table(path, table):
    """Replace the table between the two markers of `path` (the text around
    it is kept), or write a new file holding only the table."""
    text = open(path).read() if os.path.exists(path) else ''
    parts = text.split(MARK)
    if len(parts) == 3:
        text = parts[0] + table + parts[2]
    else:
        text = '# Render time: `diffraction` against `roughconductor`\n\n' + table + '\n'
    with open(path, 'w') as f:
        f.write(text)


if __name__ == '__main__':
    main()
