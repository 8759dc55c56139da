#!/usr/bin/env python3
"""gpu_check.py: the JIT path of the `diffraction` plugin on a CUDA GPU.

    .venv/bin/python scripts/gpu_check.py [--variant cuda_ad_rgb] [--quick]
        [--checks accuracy,chi2,freeze,speed] [--spp N]

(--variant llvm_ad_rgb runs the same checks on the CPU: a dry run of the script.)

Runs, in a cuda_ad_* variant with Dr.Jit's default flags (symbolic loops and
calls), the checks the issue asks of the JIT path (docs/jit.md):
  accuracy  the plugin's eval / cos against the core through ctypes
            (python/stam_diffraction/core.py) at random and grazing directions,
            for the materials of tests/materials.json tagged plugin and compare
            and the demo's Gaussian height map (`make heightmaps`);
            spectral variants at four fixed wavelengths;
  chi2      Mitsuba's chi-square test of sample against pdf (glossy context) for
            the plugin-chi2 materials at normal (not gratings), oblique and
            grazing incidence;
  freeze    a dr.freeze-d render run twice (the second call replays); skipped,
            with Mitsuba's error, where Mitsuba cannot freeze a render of the
            variant without the plugin either (3.9.1, spectral variants: its
            CIE table is not traversed; tests/test_jit_render.py skips alike);
  speed     the render of scripts/bench_render.py's scene (a sphere filling 66%
            of the frame) against the same scene with roughconductor, fastest of
            a few renders after a warm-up.
Where the machine has no CUDA device (or the Mitsuba build no CUDA variant) it
says so and exits 0. Exit status 1 when a check fails.
"""

import argparse
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(ROOT, 'python'))
import stam_accuracy as acc  # noqa: E402
import stam_diffraction  # noqa: E402,F401  (plugin path, LLVM, Dr.Jit cache)
from stam_diffraction import core as stam_core  # noqa: E402
import stam_materials  # noqa: E402
import stam_mitsuba  # noqa: E402

WAVELENGTHS = (450.0, 520.0, 590.0, 660.0)
# The tolerances (scripts/stam_accuracy.py): spectral 1e-4 relative,
# RGB the core's documented error of each model, both beyond the core's own
# spread under one-ulp changes of the f32 inputs.
SPECTRAL_TOL = acc.SPECTRAL_TOL


def cuda_available(variant):
    import mitsuba as mi
    if variant not in mi.variants():
        return False, 'this Mitsuba build has no variant %s' % variant
    if variant.startswith('llvm'):  # a dry run of the checks on the CPU
        mi.set_variant(variant)
        return True, ''
    try:
        import drjit as dr
        if not dr.has_backend(dr.JitBackend.CUDA):
            return False, 'no CUDA device (Dr.Jit has no CUDA backend here)'
        mi.set_variant(variant)
    except Exception as e:  # noqa: BLE001 (any failure to start CUDA)
        return False, 'CUDA unavailable: %s' % e
    return True, ''


def directions(n, seed):
    """Unit directions above the horizon, a quarter of them grazing."""
    rng = np.random.default_rng(seed)
    z = rng.random(n)
    z[: n // 4] *= 0.02
    z = np.maximum(z, 1e-4)
    phi = 2 * math.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def make_si(mi, dr, wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi.T.astype(np.float32))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.5, 0.5)
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    if mi.is_spectral:
        si.wavelengths = [mi.Float(w) for w in WAVELENGTHS]
    return si


def accuracy_materials():
    """The materials of tests/materials.json tagged plugin or compare, and
    the demo's Gaussian height map where `make heightmaps` wrote it."""
    import bench_render
    out = [m for m in stam_materials.load() if {'plugin', 'compare'} & set(m['tags'])]
    if os.path.exists(bench_render.HEIGHTMAP):
        out.append({'name': 'heightmap_gaussian_map', 'tags': ['plugin'],
                    'params': {'surface': 'heightmap', 'file': bench_render.HEIGHTMAP,
                               'pixel_um': 0.08}})
    else:
        print('[gpu_check] accuracy heightmap: skipped, no %s (make heightmaps)'
              % os.path.relpath(bench_render.HEIGHTMAP, ROOT), flush=True)
    return out


def check_accuracy(mi, dr, n):
    failed = []
    spectral = mi.is_spectral
    for m in accuracy_materials():
        params = m['params']
        bsdf = mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(m['params'])})
        wi, wo = directions(n, 1), directions(n, 2)
        wo[::4] = (np.array([-1, -1, 1]) * wi[::4] + 0.02 * (np.random.default_rng(3)
                   .random((len(wi[::4]), 3)) - 0.5) * [1, 1, 0])
        wo /= np.linalg.norm(wo, axis=1)[:, None]
        wo[:, 2] = np.maximum(wo[:, 2], 1e-4)
        wo /= np.linalg.norm(wo, axis=1)[:, None]
        si = make_si(mi, dr, wi, n)
        ctx = mi.BSDFContext()
        value = bsdf.eval(ctx, si, mi.Vector3f(wo.T.astype(np.float32)))
        got = np.array(value, dtype=np.float64)
        got = got.reshape(-1, n).T if got.ndim > 1 or got.size != n else got[:, None]
        got = got / wo[:, 2:3].astype(np.float32)
        core = stam_core.Brdf(params)
        wi32, wo32 = acc.as_f32(wi), acc.as_f32(wo)
        lam = np.broadcast_to(np.asarray(WAVELENGTHS, dtype=np.float32), (n, 4))
        if spectral:
            def f(a, o, lam):
                return np.stack([core.eval_spectral(a, o, lam[:, j]) for j in range(4)], axis=1)
            tol, axis = SPECTRAL_TOL, None
        else:
            def f(a, o, _lam):
                return core.eval_rgb(a, o)
            tol, axis = acc.RGB_DOCUMENTED[stam_materials.model_of(params)], 1
        ref = f(wi32, wo32, lam)
        spread = acc.conditioning(f, ref, (wi32, wo32, lam), axis)
        err = float(np.max(acc.relative_errors(got, ref, axis) - spread))
        bad = not (np.all(np.isfinite(got)) and np.all(got >= 0))
        status = 'FAIL' if (err > tol or bad) else 'ok'
        print('[gpu_check] accuracy %-24s max rel. error beyond the f32 inputs\' spread '
              '%.2e (tolerance %.1e)  %s' % (m['name'], err, tol, status), flush=True)
        if status != 'ok':
            failed.append('accuracy ' + m['name'])
    return failed


def check_chi2(mi, dr, quick):
    failed = []
    wis = {'normal': [0.0, 0.0, 1.0], 'oblique': [0.3, 0.2, math.sqrt(1 - 0.13)],
           'grazing': [math.sqrt(1 - 0.1 ** 2), 0.0, 0.1]}
    ctx = mi.BSDFContext()
    ctx.type_mask = +mi.BSDFFlags.GlossyReflection
    for m in stam_materials.load():
        if 'plugin-chi2' not in m['tags']:
            continue
        bsdf = mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(m['params'])})
        for name, wi in wis.items():
            def make(n):
                si = dr.zeros(mi.SurfaceInteraction3f, n)
                si.wi = wi
                si.uv = [0.5, 0.5]
                if mi.is_spectral:
                    si.wavelengths = list(WAVELENGTHS)
                return si

            def sample_func(sample, *args):
                bs, _ = bsdf.sample(ctx, make(dr.width(sample)), sample[0],
                                    mi.Vector2f([sample[1], sample[2]]))
                delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
                return bs.wo, dr.select((bs.pdf > 0) & ~delta, 1.0, 0.0)

            def pdf_func(wo, *args):
                return bsdf.pdf(ctx, make(dr.width(wo)), wo)

            test = mi.chi2.ChiSquareTest(domain=mi.chi2.SphericalDomain(),
                                         sample_func=sample_func, pdf_func=pdf_func,
                                         sample_dim=3,
                                         sample_count=100000 if quick else 400000,
                                         res=101,
                                         # gratings' narrow peaks: more points per cell
                                         ires=32 if m['model'] == 'periodic' else 8)
            ok = test.run()
            print('[gpu_check] chi2 %-22s %-8s %s' % (m['name'], name, 'ok' if ok else 'FAIL'),
                  flush=True)
            if not ok:
                failed.append('chi2 %s %s' % (m['name'], name))
    return failed


def check_freeze(mi, dr, scenes, spp):
    """A dr.freeze-d render of the Gaussian scene, recorded once and replayed
    with another seed, equals the plain render."""
    why = stam_mitsuba.freeze_failure(scenes['roughconductor'], spp=1)
    if why is not None:
        print('[gpu_check] freeze: skipped, Mitsuba %s cannot freeze a render in %s without '
              'the plugin either: %s' % (mi.__version__, mi.variant(), why[:200]), flush=True)
        return []
    # rendered before the recording: recorded before any plain render of the
    # scene, the second call recorded again (llvm_ad_rgb, 2 recordings; the
    # tests' frozen renders, tests/test_jit_render.py, also render first)
    plain = np.array(mi.render(scenes['gaussian'], spp=spp, seed=2))
    frozen = dr.freeze(lambda scene, seed: mi.render(scene, spp=spp, seed=seed))
    # opaque seeds: a literal's value is part of the recording's key
    a = np.array(frozen(scenes['gaussian'], dr.opaque(mi.UInt32, 1)))
    b = np.array(frozen(scenes['gaussian'], dr.opaque(mi.UInt32, 2)))
    same = np.allclose(b, plain, rtol=1e-4, atol=1e-6)
    print('[gpu_check] freeze: replay equals the plain render %s, seeds differ %s, '
          'recordings %d' % (same, not np.array_equal(a, b), frozen.n_recordings), flush=True)
    return [] if same and frozen.n_recordings == 1 else ['freeze']


def check_speed(mi, dr, scenes, spp, repeats):
    """Fastest of `repeats` renders after a warm-up, per material, as a ratio
    to roughconductor on the same scene."""
    best = {}
    for k, s in scenes.items():
        mi.render(s, spp=spp, seed=0)
        dr.sync_thread()
        times = []
        for r in range(repeats):
            t = time.perf_counter()
            img = mi.render(s, spp=spp, seed=r)
            dr.eval(img)
            dr.sync_thread()
            times.append(time.perf_counter() - t)
        best[k] = min(times)
    for k, t in best.items():
        print('[gpu_check] speed %-16s %.4f s  %.2fx roughconductor (%d spp, 256x256)'
              % (k, t, t / best['roughconductor'], spp), flush=True)
    return []


def bench_scenes(mi, spp):
    """scripts/bench_render.py's scene (a sphere filling 66% of the frame) with
    roughconductor and three of the plugin's materials (four with the height
    map, where `make heightmaps` wrote it)."""
    import bench_render
    materials = {'roughconductor': bench_render.MATERIALS['roughconductor (baseline)'],
                 'gaussian': bench_render.MATERIALS['diffraction gaussian (rough)'],
                 'fractal': bench_render.MATERIALS['diffraction fractal'],
                 'cd': bench_render.MATERIALS['diffraction cd']}
    if os.path.exists(bench_render.HEIGHTMAP):
        materials['heightmap'] = bench_render.MATERIALS['diffraction heightmap (gaussian map)']
    return {k: bench_render.scene(mi, b, 256, spp) for k, b in materials.items()}


CHECKS = ('accuracy', 'chi2', 'freeze', 'speed')


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--variant', default='cuda_ad_rgb')
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--checks', default=','.join(CHECKS),
                    help='comma-separated subset of %s' % ', '.join(CHECKS))
    ap.add_argument('--spp', type=int, default=None,
                    help='samples per pixel of the freeze and speed renders '
                         '(default 16 with --quick, else 64)')
    args = ap.parse_args(argv)
    checks = [c for c in args.checks.split(',') if c]
    unknown = sorted(set(checks) - set(CHECKS))
    if unknown:
        ap.error('unknown check(s) %s; choose from %s' % (', '.join(unknown), ', '.join(CHECKS)))
    ok, why = cuda_available(args.variant)
    if not ok:
        print('[gpu_check] %s: nothing to check (exit 0)' % why)
        return 0
    import mitsuba as mi
    import drjit as dr
    t0 = time.time()
    failed = []
    if 'accuracy' in checks:
        failed += check_accuracy(mi, dr, 20000 if args.quick else 200000)
    if 'chi2' in checks:
        failed += check_chi2(mi, dr, args.quick)
    spp = args.spp or (16 if args.quick else 64)
    if 'freeze' in checks or 'speed' in checks:
        scenes = bench_scenes(mi, spp)
        if 'freeze' in checks:
            failed += check_freeze(mi, dr, scenes, spp)
        if 'speed' in checks:
            failed += check_speed(mi, dr, scenes, spp, 3 if args.quick else 5)
    print('[gpu_check] %s: %d failed (%s), %.0f s' % (args.variant, len(failed),
                                                    ', '.join(failed) or 'none',
                                                    time.time() - t0))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
