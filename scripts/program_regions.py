"""Which regions of a material's program run, per lane and per SIMD packet.

A program's regions (If .. EndIf, docs/jit.md) run inside `dr::if_stmt`,
which on Dr.Jit's LLVM backend skips a packet of W lanes (8 with AVX2 f32,
16 with AVX-512) only where none of its lanes needs the region. This script
runs a program on the CPU (the core's reference executor,
`stam_diffraction.core.run_program`, which reports each region's mask) at the
directions a renderer asks for (its own SAMPLE program's directions, or
uniform ones) and prints, per region, its length in operations and the
fraction of lanes and of packets that run it, then the operations executed
per lane if every lane ran only what it needs, against those executed per
packet. The gap between the two is what divergence costs the JIT path.

Incident directions: 'coherent' (default) sorts the lanes by incident
direction, so that a packet holds neighbouring incidences with independent
random numbers (as a render's adjacent pixels at one sample index); 'random'
draws them independently per lane (as scripts/bench_calls.py does).

Usage: python scripts/program_regions.py --material '{"surface": "cd"}'
       [--kind eval_rgb|eval_spectral|pdf_rgb|pdf_spectral] [--at sampled|uniform]
       [--incidence coherent|random] [--packet 8] [--lanes 32768]
"""
import argparse
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'python'))
from stam_diffraction import core  # noqa: E402

KINDS = {'eval_rgb': core.PROGRAM_EVAL_RGB, 'eval_spectral': core.PROGRAM_EVAL_SPECTRAL,
         'pdf_rgb': core.PROGRAM_PDF_RGB, 'pdf_spectral': core.PROGRAM_PDF_SPECTRAL}
SPECTRAL = (core.PROGRAM_EVAL_SPECTRAL, core.PROGRAM_PDF_SPECTRAL)
SAMPLE_OF = {False: core.PROGRAM_SAMPLE_RGB, True: core.PROGRAM_SAMPLE_SPECTRAL}


def program(brdf, kind):
    """The program a renderer runs for a material at its built values."""
    a = brdf.export_program(kind + core.PROGRAM_AT_BUILT)
    return brdf.export_program(kind) if a is None else a


def direction(cos, phi):
    """Unit directions of polar cosines and azimuths."""
    sin = np.sqrt(1.0 - cos * cos)
    return np.stack([sin * np.cos(phi), sin * np.sin(phi), cos], -1)


def incident(n, rng, coherent):
    cos = rng.uniform(0.05, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    if coherent:
        # neighbouring lanes, neighbouring incidences: sorted along rings
        order = np.lexsort((phi, np.round(cos * 64)))
        cos, phi = cos[order], phi[order]
    return direction(cos, phi)


def inputs(brdf, kind, lanes, at, coherent, seed=1):
    """(wi, wo[, lambda]) lanes for a program kind: wo from the material's
    own SAMPLE program (glossy samples above the horizon) or uniform."""
    rng = np.random.default_rng(seed)
    spectral = kind in SPECTRAL
    wi = incident(lanes, rng, coherent)
    lam = rng.uniform(360.0, 830.0, lanes)
    if at == 'sampled':
        x = np.concatenate([wi, rng.uniform(0.0, 1.0, (lanes, 3))], -1)
        if spectral:
            x = np.concatenate([x, lam[:, None]], -1)
        out = core.run_program(program(brdf, SAMPLE_OF[spectral]), x)
        wo = out[:, :3].astype(np.float64)
        # a coherent (delta) sample or one below the horizon is not evaluated
        # by a renderer: its lane idles in the packet
        keep = (out[:, 3] == 0) & (wo[:, 2] > 0)
    else:
        wo = direction(rng.uniform(0.0, 1.0, lanes), rng.uniform(0.0, 2.0 * np.pi, lanes))
        keep = np.ones(lanes, bool)
    x = np.concatenate([wi, wo], -1)
    if spectral:
        x = np.concatenate([x, lam[:, None]], -1)
    return x.astype(np.float32), keep


def profile_program(p, x, keep, packet):
    """Runs program p (decoded) on lanes x (n, n_inputs; n a multiple of
    packet) of which `keep` work: {'regions': [(position of the If, length,
    lane fraction, packet fraction)], 'ops', 'top', 'per_lane', 'per_packet',
    'idle'}. per_lane: the operations a working lane needs (those outside
    regions plus each region it takes, its nested regions' left out), on
    average; per_packet: the vector operations its packets run, times the
    packet width, per working lane (per_lane where lanes never diverge and
    none idles). Idle lanes need nothing but stay in their packets."""
    n = len(x)
    if n % packet:
        raise ValueError('program_regions: %d lanes are not whole packets of %d' % (n, packet))
    recorded = []
    core.run_program(p, x, on_region=lambda position, mask: recorded.append((position, mask)))
    ops = [core.PROGRAM_OPS[c[0]] for c in p.code]
    end, stack = {}, []
    for i, o in enumerate(ops):
        if o == 'If':
            stack.append(i)
        elif o == 'EndIf':
            end[stack.pop()] = i
    inner = {i: end[i] - i - 1 for i in end}

    def parent(j):
        around = [i for i in end if i < j < end[i]]
        return max(around) if around else None
    own = dict(inner)
    for j in end:
        if parent(j) is not None:
            own[parent(j)] -= inner[j] + 2
    top = len(ops) - sum(inner[i] + 2 for i in end if parent(i) is None)
    regions = []
    need_lane = np.where(keep, float(top), 0.0)
    need_packet = np.full(n // packet, float(top))
    for pos, mask in recorded:
        m = np.broadcast_to(np.asarray(mask, bool), (n,)) & keep
        by_packet = m.reshape(-1, packet).any(1)
        regions.append((pos, inner[pos], float(m.mean()), float(by_packet.mean())))
        need_lane += m * own[pos]
        need_packet += by_packet * own[pos]
    working = max(int(keep.sum()), 1)
    return {'regions': regions, 'ops': len(ops), 'top': top,
            'per_lane': float(need_lane.sum() / working),
            'per_packet': float(need_packet.sum() * packet / working),
            'idle': float(1.0 - keep.mean())}


def profile(brdf, kind, lanes=32768, packet=8, at='sampled', coherent=True, seed=1):
    """profile_program for a material's program of `kind` (KINDS' values) at
    `lanes` directions (see `inputs`), cut to whole packets."""
    p = core.decode_program(program(brdf, kind))
    x, keep = inputs(brdf, kind, lanes, at, coherent, seed)
    n = len(x) // packet * packet
    return profile_program(p, x[:n], keep[:n], packet)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--material', default='{"surface": "cd"}', help='the material, as JSON')
    ap.add_argument('--kind', default='eval_rgb', choices=sorted(KINDS))
    ap.add_argument('--at', default='sampled', choices=['sampled', 'uniform'])
    ap.add_argument('--incidence', default='coherent', choices=['coherent', 'random'])
    ap.add_argument('--packet', type=int, default=8)
    ap.add_argument('--lanes', type=int, default=32768)
    a = ap.parse_args()
    brdf = core.Brdf(json.loads(a.material))
    r = profile(brdf, KINDS[a.kind], a.lanes, a.packet, a.at, a.incidence == 'coherent')
    print('%s of %s at %s directions, %s incidence, packets of %d: %d operations '
          '(%d outside regions); %.1f%% of lanes idle'
          % (a.kind, a.material, a.at, a.incidence, a.packet, r['ops'], r['top'],
             100 * r['idle']))
    print('%8s %8s %8s %9s' % ('If at', 'length', 'lanes', 'packets'))
    for pos, length, lane, pack in r['regions']:
        print('%8d %8d %7.1f%% %8.1f%%' % (pos, length, 100 * lane, 100 * pack))
    print('operations per working lane: %.0f needed, %.0f run by its packet (%.2fx)'
          % (r['per_lane'], r['per_packet'], r['per_packet'] / r['per_lane']))


if __name__ == '__main__':
    main()
