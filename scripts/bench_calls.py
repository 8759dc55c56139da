"""Time of each BSDF call of the `diffraction` materials against
`roughconductor`, per 2^20 lanes, in a JIT variant (Dr.Jit's default flags).

Where `bench_render.py` says how much slower a render is, this says which
call costs it: eval and pdf at uniform random directions, eval and pdf at the
directions the material's own `sample` returns (where a grating's orders are
taken), `sample` (with its weight, so its f and pdf), `eval_pdf` and
`eval_pdf_sample` (what Mitsuba's path tracer calls at a vertex). Incident
directions are uniform over the hemisphere per lane, so packets are less
coherent than a render's (which helps program regions there). Each time
includes tracing the call's programs into a kernel and finding it in Dr.Jit's
cache, which a render pays once: for the compact disc about 20 ms, what its
calls cost at --lanes 16384.

Usage: python scripts/bench_calls.py [--variant llvm_ad_rgb] [--materials "cd;gaussian (rough)"]
The fastest of --repeats timed calls after one untimed call; milliseconds.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_render  # noqa: E402
import stam_mitsuba  # noqa: E402

CALLS = ('eval', 'pdf', 'eval@sampled', 'pdf@sampled', 'sample', 'eval_pdf', 'eval_pdf_sample')


def material_names(arg):
    """bench_render's materials named in `arg` ("cd" matches "diffraction cd")."""
    if not arg:
        return list(bench_render.MATERIALS)
    names = []
    for want in arg.split(';'):
        hits = [k for k in bench_render.MATERIALS if k == want or k == 'diffraction ' + want]
        if not hits:
            sys.exit('bench_calls: no material %r (choose from %s)' % (want, ', '.join(bench_render.MATERIALS)))
        names += hits
    return names


def time_calls(mi, bsdf_dict, lanes, repeats):
    import drjit as dr
    bsdf = mi.load_dict(bsdf_dict)

    def directions(seed):
        rng = mi.PCG32(lanes, seed)
        return mi.warp.square_to_uniform_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))

    si = dr.zeros(mi.SurfaceInteraction3f, lanes)
    si.wi = directions(1)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Vector3f(0, 0, 1)
    si.uv = mi.Point2f(0.5, 0.5)
    if mi.is_spectral:
        si.wavelengths = mi.Spectrum(400, 500, 600, 700)
    wo = directions(2)
    ctx = mi.BSDFContext()
    rng = mi.PCG32(lanes, 7)
    s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    dr.eval(si, wo, s1, s2)
    bs, _ = bsdf.sample(ctx, si, s1, s2)
    sampled = mi.Vector3f(bs.wo)
    dr.eval(sampled)
    calls = {
        'eval': lambda: bsdf.eval(ctx, si, wo),
        'pdf': lambda: bsdf.pdf(ctx, si, wo),
        'eval@sampled': lambda: bsdf.eval(ctx, si, sampled),
        'pdf@sampled': lambda: bsdf.pdf(ctx, si, sampled),
        'sample': lambda: bsdf.sample(ctx, si, s1, s2),
        'eval_pdf': lambda: bsdf.eval_pdf(ctx, si, wo),
        'eval_pdf_sample': lambda: bsdf.eval_pdf_sample(ctx, si, wo, s1, s2),
    }
    best = {}
    for name in CALLS:
        times = []
        for _ in range(repeats + 1):
            dr.sync_thread()
            start = time.perf_counter()
            dr.eval(calls[name]())
            dr.sync_thread()
            times.append(time.perf_counter() - start)
        best[name] = min(times[1:]) * 1e3
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--variant', default='llvm_ad_rgb')
    ap.add_argument('--materials', default='', help='";"-separated names of bench_render.MATERIALS')
    ap.add_argument('--lanes', type=int, default=1 << 20)
    ap.add_argument('--repeats', type=int, default=3)
    args = ap.parse_args()
    if 'llvm' not in args.variant and 'cuda' not in args.variant:
        sys.exit('bench_calls: a JIT variant (llvm_ad_* or cuda_ad_*), not %s' % args.variant)
    mi = stam_mitsuba.setup(args.variant)
    print('%s, %d lanes, ms (fastest of %d):' % (args.variant, args.lanes, args.repeats))
    print('%-48s' % 'material' + ''.join('%16s' % c for c in CALLS))
    for name in material_names(args.materials):
        best = time_calls(mi, bench_render.MATERIALS[name], args.lanes, args.repeats)
        print('%-48s' % name + ''.join('%16.1f' % best[c] for c in CALLS), flush=True)


if __name__ == '__main__':
    main()
