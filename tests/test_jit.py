"""The JIT path of the `diffraction` plugin (issue 13): in the llvm_ad_*
variants the plugin executes the core's programs (stam_brdf_export_program,
rust-core/src/program/) with Dr.Jit operations (mitsuba-plugin/program.h), so
that it runs with Dr.Jit's DEFAULT flags: symbolic loops and calls, dr.freeze.

Every test here runs with the default flags. BSDF queries go through a
mi.BSDFPtr, so that Dr.Jit records them as a symbolic virtual call, as a
render does.

- eval against the core (stam_diffraction.core, ctypes): spectral within 1e-4
  relative, RGB within the model's documented RGB error (RGB_DOCUMENTED) of
  the pair's largest channel, at random, grazing and near-mirror directions;
- pdf and sample against the core's exported programs run on the CPU
  (run_program below: the core's CPU executor, stam_program_run): the JIT path samples with the programs' strategy, which
  may be simpler than the core's native one; the sample's pdf is the pdf at
  its direction, weight * pdf = eval, the coherent lobe's weight R / P;
- bad input (NaN, below the horizon, zero vectors, lambda = 0) gives finite,
  non-negative values;
- the plugin's program decoder refuses malformed arrays (never crashes).
Renders, Mitsuba's chi-square test of the JIT sampling and the `mitsuba`
command: tests/test_jit_render.py.

With STAM_JIT_REPORT=<file>, the measured errors
and p-values are appended to <file> as JSON lines.

Run: make core plugin && .venv/bin/python -m pytest tests/test_jit.py
"""

import gc
import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
sys.path.insert(0, os.path.join(ROOT, 'python'))
import stam_accuracy as acc  # noqa: E402
import stam_materials  # noqa: E402
# before drjit: the package sets DRJIT_LIBLLVM_PATH and DRJIT_CACHE_DIR
import stam_mitsuba  # noqa: E402
from stam_diffraction import core as stam_core  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

JIT_VARIANTS = ['llvm_ad_rgb', 'llvm_ad_spectral']
SURFACES = stam_materials.by_label('plugin')
# The shared list asks for Stam's formula (tests/materials.json); the default
# (energy conserving: Stam's f times the energy table) for two of them.
DEFAULT_ENERGY = {label + '_default': {k: v for k, v in SURFACES[label].items() if k != 'energy'}
                  for label in ('gaussian_aniso', 'cd')}
CHI2_SURFACES = stam_materials.by_label('plugin-chi2')
WAVELENGTHS = (450.0, 520.0, 590.0, 660.0)

# The tolerances (scripts/stam_accuracy.py): spectral 1e-4 relative,
# RGB the core's documented error of each model; FLOOR of the peak.
SPECTRAL_TOL = acc.SPECTRAL_TOL
RGB_DOCUMENTED = acc.RGB_DOCUMENTED
FLOOR = acc.FLOOR
# The plugin's kernels against the same program run in f32 with numpy: the
# last bits of Dr.Jit's exp, log, sin, cos, and its fused multiply-adds.
EXECUTOR_TOL = 2e-5
# The pdf programs of the Gaussian slope lobes evaluate exp of arguments in
# the tens: its f32 rounding (3.9e-5 measured above PDF_FLOOR of the peak).
PDF_TOL = 1e-4
PDF_FLOOR = 1e-3


def use(variant):
    """The variant, with Dr.Jit's default flags."""
    mi_ = stam_mitsuba.setup(variant)
    # A symbolic call traces every registered BSDF of the variant: free the
    # ones earlier tests left in reference cycles
    gc.collect()
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)
    return mi_


def report(**fields):
    path = os.environ.get('STAM_JIT_REPORT')
    if path:
        with open(path, 'a') as f:
            f.write(json.dumps(fields) + '\n')


def kinds_for(variant):
    """The kinds a variant runs: a spectral one, the spectral eval and the
    mixture programs over its 4 wavelengths (MIXTURE_KINDS)."""
    if 'spectral' in variant:
        return ('eval_spectral', 'mixture_pdf', 'mixture_sample', 'mixture_coherent')
    return ('eval_rgb', 'pdf_rgb', 'sample_rgb', 'coherent_rgb')


def programs(params, variant):
    """{kind: exported array} of the kinds the variant runs (every material
    has them: test_every_material_runs_in_symbolic_mode), as the plugin runs
    them while the parameters are the built ones: the kind's program for the
    built parameters where the core has one (STAM_PROGRAM_AT_BUILT: a
    Gaussian metal's RGB eval, a grating's RGB eval), else the plain one."""
    with stam_core.Brdf(params) as b:
        got = {k: export_program(b, k, at_built=True) for k in kinds_for(variant)}
        got = {k: v if v is not None else export_program(b, k) for k, v in got.items()}
    missing = [k for k, v in got.items() if v is None]
    assert not missing, (missing, params)
    return got


def to_np(x):
    # Evaluated first: converted in place, a Color3f's channels would be
    # written at offsets n and 2n by the kernel that computes them
    # (own(), below)
    dr.eval(x)
    return np.array(x, dtype=np.float64)


def own(x):
    """x (a Dr.Jit array made from numpy arrays) evaluated in memory that
    Dr.Jit allocated. A kernel then reads it as it reads any evaluated
    array, in the same code whatever the number of lanes: converted in
    place, a (3, n) array is gathered at offsets n and 2n, and a buffer
    Dr.Jit maps may be unaligned, and either made the same method's kernel
    differ from one test to the next (a cold run compiled the compact
    disc's RGB eval three times). x * 1 with an opaque 1 is x, bit for
    bit (NaN, infinities and -0 included)."""
    x = x * dr.opaque(mi.Float, 1.0)
    dr.eval(x)
    return x


def make_si(wi, wavelengths=WAVELENGTHS):
    """Interactions with local frame = world (wi: (n, 3)); wi and the
    wavelengths evaluated (own())."""
    wi = np.asarray(wi, dtype=np.float64)
    n = len(wi)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = own(mi.Vector3f(wi.T))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.5, 0.5)
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    if mi.is_spectral:
        lam = np.broadcast_to(np.asarray(wavelengths, dtype=np.float64), (n, 4))
        si.wavelengths = own(mi.Spectrum([mi.Float(lam[:, j]) for j in range(4)]))
    return si


class symbolic:
    """The BSDF behind a mi.BSDFPtr: its methods are recorded as a symbolic
    virtual call (Dr.Jit's default), as in a render. Holds the BSDF (a
    BSDFPtr does not keep its instance alive).

    With `evaluated`, each method evaluates all its outputs at once, in one
    kernel, from inputs in memory (own()): the kernel of a method is then
    the same in every test of a material (of the same program code) and
    variant, and a cold run compiles it once (Dr.Jit's kernel cache; the
    BSDF's registry id is the same in each test, where use() freed the
    earlier ones). Read one by one, the outputs of a call each traced and
    compiled it again. Without, the outputs are traced and left to the
    caller (a chi-square test reads a sample's direction and pdf, and its
    kernel then leaves out the weight's eval)."""

    def __init__(self, bsdf, evaluated=True):
        self.bsdf = bsdf
        self.ptr = mi.BSDFPtr(bsdf)
        self.evaluated = evaluated

    def __getattr__(self, name):
        method = getattr(self.ptr, name)
        if not self.evaluated or name not in ('eval', 'pdf', 'eval_pdf', 'sample',
                                              'eval_pdf_sample'):
            return method

        def evaluated(ctx, si, *args):
            out = method(ctx, si, *[own(a) if dr.is_array_v(a) else a for a in args])
            dr.eval(out)
            return out
        return evaluated


def test_programs_for_the_built_values_run_while_the_parameters_are_those():
    """A Gaussian metal's RGB eval without its table's derivative channels
    (the core's STAM_PROGRAM_AT_BUILT program, 48 gathers fewer) runs while
    the material's parameters have the values its programs were built with;
    once sigma_um carries a gradient or has moved (by 1%, no rebuild) the
    plain program runs, and it gives the same values at the built values.
    Which one ran is seen in the operation count of Dr.Jit's kernel."""
    use('llvm_ad_rgb')
    b = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.1,
                      'corr_um': 2.0})
    assert 'eval at the built parameters' in str(b), str(b)
    wi, wo = direction_pairs(4000, seed=5)
    si, ctx = make_si(wi), mi.BSDFContext()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        def run():
            dr.kernel_history()  # clears it
            v = b.eval(ctx, si, mi.Vector3f(wo.T))
            dr.eval(v)
            ops = sum(k['operation_count'] for k in dr.kernel_history()
                      if k['type'] == dr.KernelType.JIT)
            return to_np(v), ops
        lean, lean_ops = run()
        p = mi.traverse(b)
        dr.enable_grad(p['sigma_um'])
        p.update()
        plain, plain_ops = run()
        dr.disable_grad(p['sigma_um'])
        p.update()
        again, again_ops = run()
        p['sigma_um'] = 0.101
        p.update()
        moved, moved_ops = run()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert plain_ops > lean_ops + 200 and again_ops == lean_ops and moved_ops == plain_ops, \
        (lean_ops, plain_ops, again_ops, moved_ops)
    peak = plain.max()
    assert np.max(np.abs(lean - plain)) <= 1e-5 * peak
    assert np.array_equal(again, lean)
    assert np.max(np.abs(moved - lean)) > 1e-3 * peak


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def direction_pairs(n, seed):
    """wi, wo: random over the hemisphere, grazing wi, grazing wo, near the
    mirror direction (a quarter each)."""
    rng = np.random.default_rng(seed)
    q = n // 4

    def hemi(m, zmin=0.0, zmax=1.0):
        z = rng.uniform(zmin, zmax, m)
        phi = rng.uniform(0, 2 * np.pi, m)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    wi = np.concatenate([hemi(q, 0.02), hemi(q, 0.003, 0.05), hemi(q, 0.02), hemi(n - 3 * q, 0.02)])
    wo = np.concatenate([hemi(q, 0.02), hemi(q, 0.02), hemi(q, 0.003, 0.05),
                         np.zeros((n - 3 * q, 3))])
    mir = wi[3 * q:] * [-1, -1, 1] + rng.normal(scale=0.02, size=(n - 3 * q, 3))
    mir[:, 2] = np.abs(mir[:, 2]) + 1e-3
    wo[3 * q:] = unit(mir)
    # The values a variant's f32 arrays hold, so that the core is evaluated
    # at the directions the plugin sees (near the mirror direction u = -(wi
    # + wo) is a small difference: rounding the directions to f32 alone
    # changes f by ~1e-4 relative on a compact disc's order-0 tails).
    return as_f32(wi), as_f32(wo)


as_f32 = acc.as_f32


# ---------------------------------------------------------------------------
# The core's programs: export (stam_brdf_export_program) and a numpy executor
# ---------------------------------------------------------------------------

# Kinds (STAM_PROGRAM_* of stam.h): name -> code.
PROGRAM_KINDS = {name.lower(): getattr(stam_core, 'PROGRAM_' + name) for name in (
    'EVAL_RGB', 'EVAL_SPECTRAL', 'PDF_RGB', 'PDF_SPECTRAL', 'SAMPLE_RGB', 'SAMPLE_SPECTRAL',
    'COHERENT_RGB', 'COHERENT_SPECTRAL')}


# Mixture kinds (STAM_MIXTURE_* of stam.h), over the 4 wavelengths of
# Mitsuba's spectral variants: name -> code.
MIXTURE_KINDS = {'mixture_pdf': stam_core.MIXTURE_PDF, 'mixture_sample': stam_core.MIXTURE_SAMPLE,
                 'mixture_coherent': stam_core.MIXTURE_COHERENT}


def export_program(brdf, kind, at_built=False):
    """The float32 array of stam_brdf_export_program (a mixture kind's:
    stam_brdf_export_mixture_program over 4 wavelengths) for a
    stam_diffraction.core.Brdf, or None where the material has none
    (`at_built`: the kind's program for the built parameters)."""
    flag = stam_core.PROGRAM_AT_BUILT if at_built else 0
    if kind in MIXTURE_KINDS:
        return brdf.export_mixture_program(MIXTURE_KINDS[kind] | flag, 4)
    return brdf.export_program(PROGRAM_KINDS[kind] | flag)


# Operation names of the core's programs (stam.h's STAM_OP_*, lower case).
PROGRAM_OPS = tuple(name.lower() for name in stam_core.PROGRAM_OPS)
PROGRAM_HEADER_LEN = stam_core.PROGRAM_HEADER_LEN


def program_stats(v):
    """{'inputs', 'outputs', 'instructions', 'gathers', 'tables', 'table_values',
    'params'} of an exported program array (stam_core.decode_program)."""
    p = stam_core.decode_program(v)
    gather = PROGRAM_OPS.index('gather')
    return {'inputs': p.n_inputs, 'outputs': len(p.outputs), 'instructions': len(p.code),
            'gathers': sum(1 for c in p.code if c[0] == gather), 'tables': len(p.tables),
            'table_values': int(sum(len(t) for t in p.tables)), 'params': len(p.params)}


def run_program(v, inputs, dtype=np.float64, elementary=None, params=None):
    """Runs an exported program array with the core's CPU executor
    (stam_core.run_program, stam_program_run: the reference of the plugin's
    executor, mitsuba-plugin/program.h) in `dtype`: inputs is a sequence of
    n_inputs arrays (broadcast together); returns the list of outputs.
    elementary: {op: function} for some of exp, log, sin, cos, atan2
    (float32 only). params: values by parameter slot in place of the stored
    ones."""
    ins = np.broadcast_arrays(*[np.asarray(x, dtype=dtype) for x in inputs])
    p = stam_core.decode_program(v)
    if len(ins) != p.n_inputs:
        raise ValueError('the program takes %d inputs, %d given' % (p.n_inputs, len(ins)))
    by_name = None if params is None else {name: value for (name, _), value
                                           in zip(p.params, params)}
    out = stam_core.run_program(p, np.stack(ins, axis=-1), params=by_name, dtype=dtype,
                                elementary=elementary)
    return [out[..., k].copy() for k in range(out.shape[-1])]

# ---------------------------------------------------------------------------
# eval against the core
# ---------------------------------------------------------------------------

relative_errors = acc.relative_errors


@pytest.mark.parametrize('variant', JIT_VARIANTS + ['llvm_ad_mono'])
@pytest.mark.parametrize('surface', list(SURFACES) + list(DEFAULT_ENERGY))
def test_eval_equals_the_core(variant, surface):
    """The plugin's f against the core's native f (the issue's tolerance:
    SPECTRAL_TOL, or the core's documented RGB error of the model) and
    against the same program run on the CPU in f32 (the executor's
    fidelity: EXECUTOR_TOL).

    Where f is ill-conditioned in its f32 inputs (a compact disc's order-0
    tails at grazing, near-mirror pairs: u = -(wi + wo) is a small
    difference, and a one-ulp change of a direction moves f by ~1e-4), no
    f32 evaluation can do better than that spread; it is measured with the
    core (f64) at directions and wavelengths moved by one f32 ulp, and the tolerance against
    the core is widened by it pair by pair. Two f32 runs of one program differ there
    more than elsewhere (their roundings differ: fused multiply-adds, Dr.Jit's
    elementary functions), so the executor's tolerance is widened pair by
    pair by three times that spread plus the program's own f32 rounding
    (its f32 run against its f64 run)."""
    wi, wo = direction_pairs(20000, seed=11)
    assert_eval_equals_the_core(variant, surface, wi, wo, lobes_seen=100, test='eval')


def doubly_grazing_pairs(n, seed):
    """wi and wo 0.006 to 0.3 degrees above the horizon (log-uniform),
    azimuths at random."""
    rng = np.random.default_rng(seed)

    def grazing():
        z = 1e-4 * 50.0 ** rng.uniform(0, 1, n)
        phi = rng.uniform(0, 2 * np.pi, n)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return as_f32(grazing()), as_f32(grazing())


@pytest.mark.parametrize('variant', JIT_VARIANTS)
@pytest.mark.parametrize('surface', [s for s in SURFACES if s.startswith('periodic')])
def test_gratings_at_doubly_grazing_pairs(variant, surface):
    """Both directions grazing: beta = k w -> 0, where a grating's order
    table is read at its top node and c_n -> 0 for n != 0. Read from the
    table's other end, one f32 ulp of the position was 4e-4 of the cell's
    fraction there, and the sine gratings erred by up to 1.9e-3 at such
    pairs (docs/jit_measured.md, "CUDA"; the core's test:
    spectral_kernel_at_doubly_grazing_pairs)."""
    wi, wo = doubly_grazing_pairs(8000, seed=13)
    assert_eval_equals_the_core(variant, surface, wi, wo, lobes_seen=10,
                                test='eval_doubly_grazing')


def assert_eval_equals_the_core(variant, surface, wi, wo, lobes_seen, test):
    """test_eval_equals_the_core at the pairs (wi, wo), random wavelengths;
    at least `lobes_seen` pairs above 1e-3 of the largest f; reported (with
    STAM_JIT_REPORT) as `test`."""
    use(variant)
    params = {**SURFACES, **DEFAULT_ENERGY}[surface]
    progs = programs(params, variant)
    b = symbolic(mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)}))
    rng = np.random.default_rng(12)
    lam = as_f32(rng.uniform(360.0, 830.0, size=(len(wi), 4)))
    si = make_si(wi, lam)
    got = to_np(b.eval(mi.BSDFContext(), si, mi.Vector3f(wo.T))) / wo[:, 2]
    axis = None if mi.is_spectral else 0
    with stam_core.Brdf(params) as c:
        if mi.is_spectral:
            def core(a, o, lam=lam):
                return np.stack([c.eval_spectral(a, o, lam[:, j]) for j in range(4)])
            f32 = np.stack([run32(progs['eval_spectral'], [*wi.T, *wo.T, lam[:, j]])[0]
                            for j in range(4)])
            f64 = np.stack([run_program(progs['eval_spectral'], [*wi.T, *wo.T, lam[:, j]])[0]
                            for j in range(4)])
            tol = SPECTRAL_TOL
        else:
            def core(a, o, _lam=None):
                rgb = c.eval_rgb(a, o).T
                # mono: the luminance of RGB, with the core's weights
                return (stam_core.SRGB_LUMINANCE @ rgb)[None] if mi.is_monochromatic else rgb
            f32 = np.stack(run32(progs['eval_rgb'], [*wi.T, *wo.T]))
            f64 = np.stack(run_program(progs['eval_rgb'], [*wi.T, *wo.T]))
            if mi.is_monochromatic:
                f32 = (stam_core.SRGB_LUMINANCE @ f32)[None]
                f64 = (stam_core.SRGB_LUMINANCE @ f64)[None]
            tol = RGB_DOCUMENTED[stam_materials.model_of(params)]
        ref = core(wi, wo, lam)
        spread = acc.conditioning(core, ref, (wi, wo, lam), axis)
    err = relative_errors(got, ref, axis)
    err_exec = relative_errors(got, f32.astype(np.float64), axis)
    # the program's own f32 rounding at each pair (f32 run against f64 run)
    rounding = relative_errors(f32.astype(np.float64), f64, axis)
    allowance = 3 * (rounding + spread)
    worst = np.unravel_index(np.argmax(err - spread), err.shape)[-1]
    report(test=test, variant=variant, surface=surface, max_error=float(err.max()),
           p99=float(np.quantile(err, 0.99)), beyond_conditioning=float(np.max(err - spread)),
           conditioning_max=float(spread.max()), executor_max_error=float(err_exec.max()),
           executor_beyond_allowance=float(np.max(err_exec - allowance)),
           nonzero=int(np.sum(ref > FLOOR * ref.max())))
    assert np.all(np.isfinite(got)) and np.all(got >= 0)
    assert np.sum(ref > 1e-3 * ref.max()) > lobes_seen   # the pairs saw the lobes
    assert np.max(err_exec - allowance) <= EXECUTOR_TOL, err_exec.max()
    assert np.max(err - spread) <= tol, ('worst at wi %s wo %s: plugin %s, core %s'
                                         % (wi[worst], wo[worst], got[:, worst], ref[:, worst]))


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_twist_rotates_the_frame_in_symbolic_mode(variant):
    """An anisotropic material twisted by 30 degrees: the plugin's f at (wi,
    wo) is the core's at the directions rotated by -30 degrees about the
    normal (the core's x axis is the tracks' direction)."""
    use(variant)
    params = SURFACES['gaussian_aniso']
    programs(params, variant)
    b = symbolic(mi.load_dict({'type': 'diffraction', 'twist': 30.0,
                               **stam_materials.plugin_params(params)}))
    wi, wo = direction_pairs(4000, seed=21)
    si = make_si(wi)
    got = to_np(b.eval(mi.BSDFContext(), si, mi.Vector3f(wo.T))) / wo[:, 2]
    a = math.radians(30.0)

    def rot(v):   # local -> core frame (x = the twisted tangent)
        return np.stack([math.cos(a) * v[:, 0] + math.sin(a) * v[:, 1],
                         -math.sin(a) * v[:, 0] + math.cos(a) * v[:, 1], v[:, 2]], axis=1)
    with stam_core.Brdf(params) as c:
        if mi.is_spectral:
            ref = np.stack([c.eval_spectral(rot(wi), rot(wo), lam) for lam in WAVELENGTHS])
            err, tol = relative_errors(got, ref), 1e-3
            unrotated = np.stack([c.eval_spectral(wi, wo, lam) for lam in WAVELENGTHS])
        else:
            ref = c.eval_rgb(rot(wi), rot(wo)).T
            err, tol = relative_errors(got, ref, axis=0), 1e-3
            unrotated = c.eval_rgb(wi, wo).T
    assert err.max() <= tol
    # and the twist matters here
    assert np.max(np.abs(unrotated - ref)) > 0.1 * ref.max()


# ---------------------------------------------------------------------------
# pdf, sample: against the exported programs; consistency
# ---------------------------------------------------------------------------

def _drjit_elementary():
    """Dr.Jit's exp, log, sin, cos, atan2 (LLVM backend) on numpy float32."""
    import drjit.llvm as L

    def wrap(f, arity=1):
        def g(*xs):
            shape = np.broadcast_shapes(*[np.shape(x) for x in xs])
            args = [L.Float(np.broadcast_to(np.asarray(x, dtype=np.float32), shape).ravel())
                    for x in xs]
            return np.array(f(*args), dtype=np.float32).reshape(shape)
        return g
    return {'exp': wrap(dr.exp), 'log': wrap(dr.log), 'sin': wrap(dr.sin), 'cos': wrap(dr.cos),
            'atan2': wrap(dr.atan2, 2)}


# The plugin's kernels compute in f32: the references run the programs in f32
# too (numpy, from f32 inputs), with Dr.Jit's own exp, log, sin, cos and
# atan2 (elementary=True): what is compared is then the executor (one op per
# instruction, gathers, masks, selects). Dr.Jit's exp differs from a
# correctly rounded one by a relative 2^-24 |x| log2(e), which some programs
# amplify (the anisotropic Gaussian's pdf at grazing incidence: 5e-4): that is
# the arithmetic of every Dr.Jit kernel, the program's conditioning the
# concern of the core's program tests.
def run32(prog, inputs, elementary=True):
    return run_program(prog, [np.asarray(x, dtype=np.float32) for x in inputs],
                       dtype=np.float32, elementary=_drjit_elementary() if elementary else None)


def program_pdf(progs, wi, wo, lam):
    if mi.is_spectral:
        return run32(progs['mixture_pdf'], [*wi.T, *wo.T, *lam.T])[0].astype(np.float64)
    return run32(progs['pdf_rgb'], [*wi.T, *wo.T])[0].astype(np.float64)


def program_sample(progs, wi, u, lam):
    """The SAMPLE program (spectral: the mixture's, whose u0 picks one of the
    four wavelengths)."""
    if mi.is_spectral:
        out = run32(progs['mixture_sample'], [*wi.T, *u.T, *lam.T])
    else:
        out = run32(progs['sample_rgb'], [*wi.T, *u.T])
    return np.stack(out[:3], axis=1).astype(np.float64), out[3] > 0.5


def program_coherent(progs, wi, lam):
    """(R (channels, n), the sampling probability (n,))."""
    if mi.is_spectral:
        o = run32(progs['mixture_coherent'], [*wi.T, *lam.T])
        return np.stack(o[:4]).astype(np.float64), o[4].astype(np.float64)
    o = run32(progs['coherent_rgb'], [*wi.T])
    r = np.stack(o[:3]).astype(np.float64)
    if mi.is_monochromatic:
        r = (stam_core.SRGB_LUMINANCE @ r)[None]
    return r, o[3].astype(np.float64)


@pytest.mark.parametrize('variant', JIT_VARIANTS)
@pytest.mark.parametrize('surface', list(SURFACES))
def test_pdf_and_sample_equal_the_programs(variant, surface):
    use(variant)
    params = SURFACES[surface]
    progs = programs(params, variant)
    b = symbolic(mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)}))
    ctx = mi.BSDFContext()
    n = 8000
    wi, wo = direction_pairs(n, seed=31)
    rng = np.random.default_rng(32)
    lam = np.broadcast_to(WAVELENGTHS, (n, 4)).copy()
    si = make_si(wi)

    # pdf at given directions
    pdf = to_np(b.pdf(ctx, si, mi.Vector3f(wo.T)))
    ref = program_pdf(progs, wi, wo, lam)
    # The slope lobes' far tails (exp of arguments around -30 at grazing wi)
    # are ill-conditioned in f32: Dr.Jit's exp and numpy's resolve their
    # rounding differently (measured: 4.9e-4 at 2e-5 of the peak), so the
    # pdf is compared above PDF_FLOOR of its peak.
    err_pdf = relative_errors(pdf, ref, floor=PDF_FLOOR)
    assert err_pdf.max() <= PDF_TOL, err_pdf.max()

    # samples: the program's directions; bs.pdf the pdf there (or the
    # coherent probability); weight = f cos / pdf or R / P
    u = rng.random((n, 3)).astype(np.float32).astype(np.float64)
    bs, w = b.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    swo, spdf, w = to_np(bs.wo).T, to_np(bs.pdf), to_np(w)
    coh = to_np(bs.sampled_component) == 1
    ref_wo, ref_coh = program_sample(progs, wi, u, lam)
    ok = spdf > 0
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(spdf >= 0)
    assert np.array_equal(coh[ok], ref_coh[ok])
    err_wo = np.abs(swo - ref_wo)[ok].max()
    assert err_wo <= 2e-4, err_wo
    # the failed samples are the program's (below the horizon) or have f = 0
    glossy = ok & ~coh
    assert glossy.sum() > n // 20
    v, p = b.eval_pdf(ctx, si, mi.Vector3f(swo.T))
    v, p = to_np(v), to_np(p)
    assert np.allclose(spdf[glossy], p[glossy], rtol=1e-5)
    err_w = relative_errors((w * spdf)[:, glossy], v[:, glossy])
    assert err_w.max() <= 1e-4, err_w.max()
    r, p_c = program_coherent(progs, wi, lam)
    if coh.any():
        assert np.allclose(spdf[coh], p_c[coh], rtol=1e-5)
        assert np.allclose(w[:, coh], r[:, coh] / p_c[coh], rtol=1e-4, atol=1e-7)
        mirror = wi * [-1, -1, 1]
        assert np.allclose(swo[coh], mirror[coh], atol=1e-5)
    report(test='pdf_sample', variant=variant, surface=surface, pdf_max_error=float(err_pdf.max()),
           wo_max_error=float(err_wo), weight_max_error=float(err_w.max()),
           glossy=int(glossy.sum()), coherent=int(coh.sum()))


# The plugin's methods share one executor whatever the model: their agreement
# is checked on one material of each kind of program (isotropic and anisotropic
# Gaussian, fractal, tabulated grating, the compact disc's rect grating); the
# rough Gaussian, rect and sine gratings differ from these only
# in numbers and orders (their compiles took a minute of a cold test run).
METHOD_SURFACES = ['gaussian', 'gaussian_aniso', 'fractal', 'periodic_table', 'cd']


@pytest.mark.parametrize('variant', JIT_VARIANTS)
@pytest.mark.parametrize('surface', METHOD_SURFACES)
def test_eval_pdf_and_eval_pdf_sample_agree(variant, surface):
    use(variant)
    params = SURFACES[surface]
    programs(params, variant)
    b = symbolic(mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)}))
    ctx = mi.BSDFContext()
    wi, wo = direction_pairs(2000, seed=41)
    si = make_si(wi)
    wo_ = mi.Vector3f(wo.T)
    rng = np.random.default_rng(42)
    u = rng.random((len(wi), 3))
    s1, s2 = mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2])
    v, p = b.eval(ctx, si, wo_), b.pdf(ctx, si, wo_)
    v2, p2 = b.eval_pdf(ctx, si, wo_)
    v3, p3, bs3, w3 = b.eval_pdf_sample(ctx, si, wo_, s1, s2)
    bs, w = b.sample(ctx, si, s1, s2)
    # one kernel per method (each output read alone would trace and compile
    # its method again: 13 kernels instead of 5)
    for outputs in ((v,), (p,), (v2, p2), (v3, p3, bs3, w3), (bs, w)):
        dr.eval(*outputs)
    for x, y in ((v, v2), (v, v3), (p, p2), (p, p3), (w, w3), (bs.wo, bs3.wo), (bs.pdf, bs3.pdf)):
        assert np.allclose(to_np(x), to_np(y), rtol=1e-5, atol=1e-7)


# ---------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------

@pytest.mark.parametrize('variant', JIT_VARIANTS)
@pytest.mark.parametrize('surface', list(SURFACES))
def test_bad_input_gives_finite_non_negative_values(variant, surface):
    use(variant)
    params = SURFACES[surface]
    programs(params, variant)
    b = symbolic(mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)}))
    nan, inf = float('nan'), float('inf')
    good = [0.3, 0.2, math.sqrt(1 - 0.13)]
    dirs = [[nan, 0, 1], [0, 0, nan], [0.3, 0, -0.9], [0, 0, 0], [inf, 0, 1], [1, 0, 0],
            [0, 0, 1e-30], good]
    lams = [(0.0,) * 4, (nan,) * 4, (-500.0, 1e9, inf, 550.0), WAVELENGTHS]
    # every (wi, wo, wavelengths, sample) combination in one call of each method
    cases = [(a, c, lam, u) for a in dirs for c in dirs for lam in lams
             for u in (0.0, 0.5, 1.0 - 2 ** -24)]
    wi = np.array([k[0] for k in cases], dtype=np.float64)
    wo = np.array([k[1] for k in cases], dtype=np.float64)
    lam = np.array([k[2] for k in cases], dtype=np.float64)
    u = np.array([k[3] for k in cases], dtype=np.float64)
    si = make_si(wi, lam)
    ctx = mi.BSDFContext()
    outs = [b.eval(ctx, si, mi.Vector3f(wo.T)), b.pdf(ctx, si, mi.Vector3f(wo.T))]
    bs, w = b.sample(ctx, si, mi.Float(u), mi.Point2f(u, 1 - u))
    outs += [w, bs.pdf]
    assert np.all(np.isfinite(to_np(bs.wo)))
    for o in outs:
        o = to_np(o)
        assert np.all(np.isfinite(o)) and np.all(o >= 0), o
    # the good pair at the good wavelengths answers
    ok = [i for i, k in enumerate(cases) if k[0] is good and k[1] is good and k[2] is WAVELENGTHS]
    assert np.all(to_np(outs[1])[ok] > 0)


# ---------------------------------------------------------------------------
# The decoder refuses malformed arrays
# ---------------------------------------------------------------------------

@pytest.fixture(scope='module')
def decoder(tmp_path_factory):
    """tests/program_decode/decode.cpp (mitsuba-plugin/program.h's decoder
    alone), built with the sanitizers where the compiler has them."""
    cxx = shutil.which(os.environ.get('CXX', 'g++'))
    if not cxx:
        pytest.skip('no C++ compiler')
    import drjit
    inc = os.path.join(os.path.dirname(drjit.__file__), 'include')
    exe = str(tmp_path_factory.mktemp('decoder') / 'decode')
    src = os.path.join(ROOT, 'tests', 'program_decode', 'decode.cpp')
    base = [cxx, '-std=c++17', '-O1', '-g', '-march=haswell', '-isystem', inc, src, '-o', exe]
    for extra in (['-fsanitize=address,undefined', '-fno-sanitize-recover=all'], []):
        if subprocess.run(base + extra, capture_output=True).returncode == 0:
            return exe
    pytest.fail('tests/program_decode/decode.cpp does not compile')


def decode(exe, tmp_path, values, name='p.bin'):
    path = tmp_path / name
    np.asarray(values, dtype=np.float32).tofile(path)
    r = subprocess.run([exe, str(path)], capture_output=True, text=True,
                       env=dict(os.environ, ASAN_OPTIONS='detect_leaks=0'))
    return r.returncode, r.stdout.strip() + r.stderr.strip()


def exported_programs():
    """Every program the core exports for the plugin materials."""
    out = []
    for name, params in SURFACES.items():
        with stam_core.Brdf(params) as c:
            for k in [*PROGRAM_KINDS, *MIXTURE_KINDS]:
                v = export_program(c, k)
                if v is not None:
                    out.append(('%s/%s' % (name, k), v))
    return out


def test_decoder_reads_every_exported_program(decoder, tmp_path):
    progs = exported_programs()
    assert progs
    for name, v in progs:
        rc, out = decode(decoder, tmp_path, v)
        st = program_stats(v)
        assert rc == 0 and out == 'ok %d %d %d' % (st['instructions'], st['gathers'],
                                                     st['outputs']), (name, out)
        report(test='program', name=name, **st)


def test_decoder_refuses_malformed_arrays(decoder, tmp_path):
    name, v = max(exported_programs(), key=lambda p: program_stats(p[1])['gathers'])
    v = np.asarray(v, dtype=np.float32)
    st = program_stats(v)
    n_out, n_code, n_tab = st['outputs'], st['instructions'], st['tables']
    code_at = PROGRAM_HEADER_LEN + n_out + 2 * n_tab + 2 * st['params']

    def with_(i, x):
        w = v.copy()
        w[i] = x
        return w
    op_at = {op: [code_at + 4 * i for i in range(n_code) if int(v[code_at + 4 * i]) == c]
             for c, op in enumerate(PROGRAM_OPS)}
    first_binary = op_at['add'][0] if op_at['add'] else op_at['mul'][0]
    first_mask_op = next(op_at[o][0] for o in ('lt', 'le', 'gt', 'ge', 'finite') if op_at[o])
    bad = {
        'empty': v[:0], 'truncated header': v[:5], 'truncated': v[:-1],
        'format': with_(0, 2), 'format NaN': with_(0, float('nan')),
        'length': with_(5, len(v) + 1), 'negative count': with_(3, -1),
        'fractional count': with_(2, 1.5), 'huge count': with_(3, 1e9),
        'unknown op': with_(code_at, len(PROGRAM_OPS)), 'op NaN': with_(code_at, float('nan')),
        'forward reference': with_(first_binary + 1, first_binary // 4),
        'self reference': with_(first_binary + 1, (first_binary - code_at) // 4),
        'mask as float': with_(first_binary + 1, (first_mask_op - code_at) // 4),
        'input out of range': with_(op_at['input'][0] + 1, 99),
        'output out of range': with_(8, n_code),
        'output is a mask': with_(8, (first_mask_op - code_at) // 4),
        'extra value': np.append(v, 0.0),
    }
    if op_at['gather']:
        g = op_at['gather'][0]
        bad['table out of range'] = with_(g + 1, n_tab)
    if n_tab:
        bad['table past the end'] = with_(8 + n_out + 1, len(v))
        bad['table inside the code'] = with_(8 + n_out, code_at)
    for what, w in bad.items():
        rc, out = decode(decoder, tmp_path, w)
        assert rc == 1 and out.startswith('malformed'), (what, rc, out)
    # random corruption: refused or read, never a crash (the sanitizers
    # abort on any read outside the array)
    rng = np.random.default_rng(7)
    values = [float('nan'), float('inf'), -1.0, 0.5, 1e9, 2.0 ** 24, 0.0, 3.0]
    for t in range(120):
        w = v.copy()
        for _ in range(rng.integers(1, 4)):
            i = rng.integers(0, code_at + 4 * n_code)
            w[i] = values[rng.integers(len(values))] if rng.random() < 0.5 else \
                float(rng.integers(0, 2 * max(n_code, 30)))
        rc, out = decode(decoder, tmp_path, w)
        assert rc in (0, 1), (t, rc, out)
