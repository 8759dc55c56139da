"""Tests of the Mitsuba `diffraction` BSDF plugin (build/plugins/diffraction.so).

Patterns follow Mitsuba's own BSDF tests (src/bsdfs/tests): creation and flags,
eval == eval_pdf[0], pdf == eval_pdf[1], chi2 of sample vs pdf, sample weight
* pdf == eval, bs.pdf == pdf(bs.wo); plus checks against the core's C ABI
(target/release/libstam.so through stam_diffraction.core), the Beckmann limit
(Mitsuba's roughconductor), bad parameters, and renders in every supported
variant. The materials are those of tests/materials.json tagged `plugin` and
`plugin-chi2`.

Run: make core plugin && .venv/bin/python -m pytest tests/test_plugin.py
"""

import math
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
sys.path.insert(0, os.path.join(ROOT, 'python'))
import stam_materials  # noqa: E402
# before drjit: the package sets DRJIT_LIBLLVM_PATH and DRJIT_CACHE_DIR
import stam_mitsuba  # noqa: E402
from stam_diffraction import core as stam_core  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

SCALAR_VARIANTS = ['scalar_rgb', 'scalar_spectral']
LLVM_VARIANTS = ['llvm_ad_rgb', 'llvm_ad_spectral', 'llvm_ad_mono']
ALL_VARIANTS = SCALAR_VARIANTS + LLVM_VARIANTS

# One configuration per surface model (core JSON names, micrometres)
SURFACES = stam_materials.by_label('plugin')

# Mitsuba's chi-square test integrates the pdf on a fixed 101 x 202 grid, so
# the plugin-level tests use lobes several cells wide; the core's own
# chi-square tests (rust-core/src/testing/chi2.rs, adaptive cells) cover the
# narrow ones, the default compact disc included.
CHI2_SURFACES = stam_materials.by_label('plugin-chi2')

WI_LIST = [[0.0, 0.0, 1.0],
           [0.3, 0.2, math.sqrt(1 - 0.13)],
           [math.sqrt(1 - 0.05 ** 2), 0.0, 0.05]]   # grazing


def use(variant):
    return stam_mitsuba.setup(variant)


def bsdf_dict(surface, **extra):
    d = {'type': 'diffraction'}
    d.update(stam_materials.plugin_params(SURFACES[surface]))
    d.update(extra)
    return d


def chi2_bsdf_dict(surface):
    return {'type': 'diffraction', **stam_materials.plugin_params(CHI2_SURFACES[surface])}


def make_si(wi, n=1, wavelengths=(450.0, 520.0, 590.0, 660.0), uv=(0.5, 0.5)):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(uv)
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    if mi.is_spectral:
        si.wavelengths = list(wavelengths)
    return si


def hemisphere_dirs(n, seed=1, min_z=0.02):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    v[:, 2] = np.abs(v[:, 2])
    v = v[v[:, 2] > min_z]
    return v


def to_np(x):
    return np.array(x, dtype=np.float64)


# ---------------------------------------------------------------------------
# Creation and flags
# ---------------------------------------------------------------------------

@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
@pytest.mark.parametrize('surface', list(SURFACES))
def test01_create(variant, surface):
    use(variant)
    b = mi.load_dict(bsdf_dict(surface))
    assert b is not None
    n = b.component_count()
    assert n in (1, 2)
    assert mi.has_flag(b.flags(0), mi.BSDFFlags.GlossyReflection)
    assert mi.has_flag(b.flags(0), mi.BSDFFlags.FrontSide)
    if n == 2:
        assert mi.has_flag(b.flags(1), mi.BSDFFlags.DeltaReflection)
    total = 0
    for i in range(n):
        total |= int(b.flags(i))
    assert int(b.flags()) == total
    # Gaussian surfaces have a coherent lobe, fractal and periodic ones do not
    if surface.startswith('gaussian'):
        assert n == 2
    if surface.startswith('periodic') or surface == 'cd':
        assert mi.has_flag(b.flags(0), mi.BSDFFlags.Anisotropic)
    assert 'Diffraction[' in str(b)


@pytest.mark.parametrize('variant', ['scalar_rgb'])
def test02_anisotropic_flag_for_twist_and_tracks(variant):
    use(variant)
    b = mi.load_dict(bsdf_dict('gaussian', twist=10.0))
    assert mi.has_flag(b.flags(0), mi.BSDFFlags.Anisotropic)
    b = mi.load_dict(bsdf_dict('cd', tracks='concentric'))
    assert mi.has_flag(b.flags(0), mi.BSDFFlags.Anisotropic)


def test03_cuda_without_a_device_is_named():
    """cuda_* variants run the core's programs on the GPU (scripts/gpu_check.py);
    without a CUDA device setup() says so instead of Dr.Jit's error."""
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip('a CUDA device is present: scripts/gpu_check.py checks it')
    with pytest.raises(RuntimeError, match='CUDA device'):
        stam_mitsuba.setup('cuda_ad_rgb')


# ---------------------------------------------------------------------------
# eval / pdf / eval_pdf / eval_pdf_sample consistency
# ---------------------------------------------------------------------------

@pytest.mark.parametrize('variant', ['scalar_rgb', 'scalar_spectral'])
@pytest.mark.parametrize('surface', ['gaussian', 'fractal', 'periodic_rect', 'cd'])
def test04_eval_pdf_scalar(variant, surface):
    use(variant)
    b = mi.load_dict(bsdf_dict(surface))
    ctx = mi.BSDFContext()
    for wi in WI_LIST:
        si = make_si(wi)
        for wo in hemisphere_dirs(40):
            wo = mi.Vector3f(wo)
            v = b.eval(ctx, si, wo)
            p = b.pdf(ctx, si, wo)
            v2, p2 = b.eval_pdf(ctx, si, wo)
            assert np.allclose(to_np(v), to_np(v2), rtol=1e-5, atol=1e-7)
            assert np.isclose(float(p), float(p2), rtol=1e-5, atol=1e-7)
            assert np.all(np.isfinite(to_np(v))) and np.all(to_np(v) >= 0)
            v3, p3, _, _ = b.eval_pdf_sample(ctx, si, wo, 0.3, mi.Point2f(0.4, 0.6))
            assert np.allclose(to_np(v), to_np(v3), rtol=1e-5, atol=1e-7)
            assert np.isclose(float(p), float(p3), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
@pytest.mark.parametrize('surface', ['gaussian', 'fractal', 'periodic_rect', 'cd'])
def test05_eval_pdf_vectorized(variant, surface):
    use(variant)
    b = mi.load_dict(bsdf_dict(surface))
    ctx = mi.BSDFContext()
    d = hemisphere_dirs(500)
    wo = mi.Vector3f(d[:, 0], d[:, 1], d[:, 2])
    for wi in WI_LIST:
        si = make_si(wi, n=len(d))
        v = b.eval(ctx, si, wo)
        p = b.pdf(ctx, si, wo)
        v2, p2 = b.eval_pdf(ctx, si, wo)
        assert np.allclose(to_np(v), to_np(v2), rtol=1e-5, atol=1e-7)
        assert np.allclose(to_np(p), to_np(p2), rtol=1e-5, atol=1e-7)
        assert np.all(np.isfinite(to_np(v))) and np.all(np.isfinite(to_np(p)))


@pytest.mark.parametrize('variant', ['scalar_spectral', 'llvm_ad_spectral'])
def test06_zero_wavelength_is_safe(variant):
    """Mitsuba's chi2 adapter leaves si.wavelengths at 0."""
    use(variant)
    b = mi.load_dict(bsdf_dict('gaussian'))
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(0, 0, 1)
    ctx = mi.BSDFContext()
    v, p = b.eval_pdf(ctx, si, mi.Vector3f(0.1, 0, math.sqrt(0.99)))
    assert np.all(np.isfinite(to_np(v))) and np.all(np.isfinite(to_np(p)))
    bs, w = b.sample(ctx, si, 0.5, mi.Point2f(0.3, 0.3))
    assert np.all(np.isfinite(to_np(w)))


# ---------------------------------------------------------------------------
# Sampling: chi2, weight * pdf == eval, bs.pdf == pdf(bs.wo)
# ---------------------------------------------------------------------------

def density_adapter(bsdf, wi, ctx, wavelengths=None, uv=(0.5, 0.5)):
    """Like mi.chi2.BSDFAdapter, but (a) with non-zero wavelengths in spectral
    variants and (b) counting every sample of the glossy lobe whatever its
    weight: the test compares the sampling density with the pdf, and
    mi.chi2.BSDFAdapter drops zero-weight samples (directions where f = 0 but
    the defensive part of the strategy still samples, e.g. between the orders
    of a grating), which the pdf rightly includes.

    In JIT variants wi is put in memory (opaque): a literal wi made each
    incidence's kernels differ, which a cold run compiled once per
    incidence; in memory, the incidences of a material share them."""
    if dr.is_jit_v(mi.Float):
        wi = dr.opaque(mi.Vector3f, wi)

    def make_si_n(n):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = wi
        si.uv = list(uv)
        if wavelengths is not None:
            si.wavelengths = list(wavelengths)
        return si

    def sample_functor(sample, *args):
        n = dr.width(sample)
        bs, weight = bsdf.sample(ctx, make_si_n(n), sample[0],
                                 mi.Vector2f([sample[1], sample[2]]))
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        w = dr.select((bs.pdf > 0) & ~delta, 1.0, 0.0)
        return bs.wo, w

    def pdf_functor(wo, *args):
        return bsdf.pdf(ctx, make_si_n(dr.width(wo)), wo)

    return sample_functor, pdf_functor


def chi2_test(sample_func, pdf_func, surface):
    # Integration points per cell: 8 resolve the smooth models' lobes; the
    # gratings' peaks need 32 (8 read the pdf up to 1% off in the peaks' cells)
    periodic = surface.startswith('periodic') or surface == 'cd'
    return mi.chi2.ChiSquareTest(domain=mi.chi2.SphericalDomain(),
                                 sample_func=sample_func, pdf_func=pdf_func,
                                 sample_dim=3, sample_count=400000, res=101,
                                 ires=32 if periodic else 8)


def glossy_ctx():
    ctx = mi.BSDFContext()
    ctx.type_mask = +mi.BSDFFlags.GlossyReflection   # the delta lobe has no density
    return ctx


# Gratings at normal incidence put a sharp order-0 peak on the pole of
# Mitsuba's spherical grid, whose fixed-grid pdf integration then reads 5-14%
# high although the density integrates to 1 (the core's chi-square tests,
# rust-core/src/testing/chi2.rs, integrate it on adaptive cells, normal incidence
# included); they are tested here at oblique and grazing incidence.
CHI2_CASES = [(s, i) for s in ('gaussian', 'gaussian_aniso', 'fractal') for i in range(3)] + \
    [(s, i) for s in ('periodic_rect', 'periodic_sine', 'cd') for i in (1, 2)]


@pytest.mark.parametrize('surface,wi_index', CHI2_CASES)
def test07_chi2_rgb(surface, wi_index):
    wi = WI_LIST[wi_index]
    use('llvm_ad_rgb')
    b = mi.load_dict(chi2_bsdf_dict(surface))
    chi2 = chi2_test(*density_adapter(b, wi, glossy_ctx()), surface)
    assert chi2.run(), chi2.messages


@pytest.mark.parametrize('surface,wi_index', [('gaussian', 1), ('gaussian', 2), ('fractal', 1),
                                              ('fractal', 2), ('periodic_rect', 1)])
def test08_chi2_spectral(surface, wi_index):
    wi = WI_LIST[wi_index]
    """Sampling with a hero wavelength, pdf = mean over the four wavelengths."""
    use('llvm_ad_spectral')
    b = mi.load_dict(chi2_bsdf_dict(surface))
    chi2 = chi2_test(*density_adapter(b, wi, glossy_ctx(), (450.0, 520.0, 590.0, 660.0)), surface)
    assert chi2.run(), chi2.messages


@pytest.mark.parametrize('variant', ['scalar_rgb', 'scalar_spectral'])
@pytest.mark.parametrize('surface', ['gaussian', 'fractal', 'periodic_rect', 'cd'])
def test09_sample_weight_and_pdf(variant, surface):
    use(variant)
    b = mi.load_dict(bsdf_dict(surface))
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(3)
    n_glossy = 0
    for wi in WI_LIST:
        si = make_si(wi)
        for _ in range(60):
            s = rng.random(3)
            bs, w = b.sample(ctx, si, float(s[0]), mi.Point2f(float(s[1]), float(s[2])))
            w = to_np(w)
            assert np.all(np.isfinite(w)) and np.all(w >= 0)
            if np.all(w == 0):
                continue
            if mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection):
                assert bs.sampled_component == 1
                # the mirror direction
                assert np.allclose(to_np(bs.wo), [-wi[0], -wi[1], wi[2]], atol=1e-4)
                continue
            n_glossy += 1
            assert bs.sampled_component == 0
            v, p = b.eval_pdf(ctx, si, bs.wo)
            assert np.isclose(float(bs.pdf), float(p), rtol=1e-3)
            assert np.allclose(w * float(bs.pdf), to_np(v), rtol=1e-3, atol=1e-6)
    assert n_glossy > 0


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test10_sample_weight_and_pdf_vectorized(variant):
    use(variant)
    # Rough enough that the coherent lobe (excluded by the glossy context)
    # leaves a fair share of samples even at grazing incidence.
    b = mi.load_dict(bsdf_dict('gaussian_rough'))
    ctx = glossy_ctx()
    n = 2000
    rng = np.random.default_rng(4)
    s = rng.random((n, 3))
    for wi in WI_LIST:
        si = make_si(wi, n=n)
        bs, w = b.sample(ctx, si, mi.Float(s[:, 0]), mi.Point2f(s[:, 1], s[:, 2]))
        v, p = b.eval_pdf(ctx, si, bs.wo)
        w, v, p, bp = to_np(w), to_np(v), to_np(p), to_np(bs.pdf)
        ok = np.any(w > 0, axis=0)
        assert ok.sum() > n // 10
        assert np.allclose(bp[ok], p[ok], rtol=1e-3)
        assert np.allclose((w * bp)[:, ok], v[:, ok], rtol=1e-3, atol=1e-6)


# ---------------------------------------------------------------------------
# The plugin forwards to the core: eval == core f * cos
# ---------------------------------------------------------------------------

def core_eval(surface, wi, wo, lam=None):
    """The core's f (without cos) through its C ABI: (n, 3) RGB, or (n,) at
    the wavelength lam."""
    with stam_core.Brdf(SURFACES[surface]) as b:
        return b.eval_rgb(wi, wo) if lam is None else b.eval_spectral(wi, wo, lam)


@pytest.mark.parametrize('surface', ['gaussian', 'gaussian_aniso', 'fractal', 'periodic_rect'])
def test11_plugin_equals_core_times_cos(surface):
    use('scalar_rgb')
    b = mi.load_dict(bsdf_dict(surface))
    ctx = mi.BSDFContext()
    wo = hemisphere_dirs(50, seed=7)
    for wi in WI_LIST[:2]:
        ref = core_eval(surface, wi, wo) * wo[:, 2:3]
        si = make_si(wi)
        got = np.array([to_np(b.eval(ctx, si, mi.Vector3f(d))) for d in wo])
        assert np.allclose(got, ref, rtol=1e-5, atol=1e-8)

    use('scalar_spectral')
    b = mi.load_dict(bsdf_dict(surface))
    lams = (450.0, 520.0, 590.0, 660.0)
    wi = WI_LIST[1]
    si = make_si(wi, wavelengths=lams)
    got = np.array([to_np(b.eval(ctx, si, mi.Vector3f(d))) for d in wo])
    for j, lam in enumerate(lams):
        ref = core_eval(surface, wi, wo, lam) * wo[:, 2]
        assert np.allclose(got[:, j], ref, rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize('twist', [30.0, 90.0])
def test12_twist_rotates_the_frame(twist):
    """twist = t: the core sees directions rotated by -t about the normal."""
    use('scalar_rgb')
    surface = 'periodic_rect'
    b = mi.load_dict(bsdf_dict(surface, twist=twist))
    ctx = mi.BSDFContext()
    t = math.radians(twist)
    c, s = math.cos(t), math.sin(t)

    def rot(v):   # world (local shading) -> core frame
        return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])
    wi = WI_LIST[1]
    wo = hemisphere_dirs(40, seed=9)
    ref = core_eval(surface, rot(wi), np.array([rot(d) for d in wo]))
    ref *= wo[:, 2:3]
    si = make_si(wi)
    got = np.array([to_np(b.eval(ctx, si, mi.Vector3f(d))) for d in wo])
    assert np.allclose(got, ref, rtol=1e-4, atol=1e-7)


def test13_concentric_tracks_frame():
    """On a uv square with dp_du = x, dp_dv = y and centre (0.5, 0.5): at
    uv = (0.8, 0.5) the periodic direction is +x (like linear tracks); at
    uv = (0.5, 0.8) it is +y (like twist = 90)."""
    use('scalar_rgb')
    ctx = mi.BSDFContext()
    conc = mi.load_dict(bsdf_dict('cd', tracks='concentric'))
    lin0 = mi.load_dict(bsdf_dict('cd'))
    lin90 = mi.load_dict(bsdf_dict('cd', twist=90.0))
    wi = WI_LIST[1]
    for d in hemisphere_dirs(40, seed=11):
        wo = mi.Vector3f(d)
        a = to_np(conc.eval(ctx, make_si(wi, uv=(0.8, 0.5)), wo))
        r = to_np(lin0.eval(ctx, make_si(wi), wo))
        assert np.allclose(a, r, rtol=1e-4, atol=1e-7)
        a = to_np(conc.eval(ctx, make_si(wi, uv=(0.5, 0.8)), wo))
        r = to_np(lin90.eval(ctx, make_si(wi), wo))
        assert np.allclose(a, r, rtol=1e-4, atol=1e-7)


# ---------------------------------------------------------------------------
# External oracle: the Beckmann limit (physics.md)
# ---------------------------------------------------------------------------

def test14_beckmann_limit():
    """Large g: f -> D_Beckmann(alpha = 2 sigma / T) / (4 cos_i cos_o) with F = 1;
    Mitsuba's roughconductor (material none: F = 1) agrees near normal incidence
    where Smith shadowing ~ 1."""
    use('scalar_rgb')
    sigma, T = 0.5, 5.0
    alpha = 2 * sigma / T
    ours = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian',
                         'sigma_um': sigma, 'corr_um': T, 'fresnel': 1.0})
    ref = mi.load_dict({'type': 'roughconductor', 'distribution': 'beckmann',
                        'alpha': alpha, 'material': 'none'})
    ctx = mi.BSDFContext()
    wi = [0.05, 0.0, math.sqrt(1 - 0.05 ** 2)]
    si = make_si(wi)
    checked = 0
    for th in np.linspace(0.0, 1.2 * alpha, 7):
        for ph in np.linspace(0, 2 * math.pi, 8, endpoint=False):
            h = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
            wo = 2 * np.dot(wi, h) * h - np.array(wi)
            if wo[2] < 0.9:
                continue
            a = to_np(ours.eval(ctx, si, mi.Vector3f(wo)))
            r = to_np(ref.eval(ctx, si, mi.Vector3f(wo)))
            assert np.allclose(a, r, rtol=0.03), (th, ph, a, r)
            checked += 1
    assert checked > 20


# ---------------------------------------------------------------------------
# Parameters: errors, traverse
# ---------------------------------------------------------------------------

# Each entry is valid but for the named key, so the refusal must name it.
_G = {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_um': 2.0}
_P = {'surface': 'periodic', 'period_um': 2.0, 'coherence_um': 10.0,
      'profile': 'sine', 'height_um': 0.2}
BAD = [
    ({'surface': 'banana'}, 'surface'),
    ({**_G, 'sigma_um': -1.0}, 'sigma_um'),
    ({**_G, 'corr_um': 0.0}, 'corr_um'),
    ({**_G, 'sigmaa_um': 0.1}, 'sigmaa_um'),
    ({'surface': 'fractal', 'sigma_um': 0.1, 'lag_um': 1.0, 'hurst': 1.5}, 'hurst'),
    ({**_P, 'period_um': -2.0}, 'period_um'),
    ({**_P, 'profile': 'triangle'}, 'profile'),
    ({**_G, 'fresnel': 'unobtainium'}, 'fresnel'),
    ({**_G, 'fresnel': 0.5, 'eta': 1.2, 'k': 3.0}, 'fresnel'),
    ({**_G, 'tracks': 'spiral'}, 'tracks'),
    ({**_G, 'center_u': 0.3}, 'center_u'),
]


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
@pytest.mark.parametrize('params,name', BAD)
def test15_bad_parameters_refused_by_name(variant, params, name):
    use(variant)
    with pytest.raises(Exception) as e:
        mi.load_dict(dict({'type': 'diffraction'}, **params))
    assert 'diffraction' in str(e.value) and name in str(e.value), str(e.value)


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test16_traverse_and_update(variant):
    use(variant)
    b = mi.load_dict(bsdf_dict('gaussian', fresnel=0.8))
    params = mi.traverse(b)
    for k in ('sigma_um', 'corr_um', 'fresnel', 'twist'):
        assert k in params
    # strings travel as a mi.Properties whose plugin name is the value
    assert params['surface'].plugin_name() == 'gaussian'
    ctx = mi.BSDFContext()
    si = make_si(WI_LIST[1])
    wo = mi.Vector3f(-0.2, -0.1, math.sqrt(0.95))
    v0 = to_np(b.eval(ctx, si, wo))
    params['fresnel'] = 0.4
    params.update()
    v1 = to_np(b.eval(ctx, si, wo))
    assert np.all(v1 < v0)
    assert '0.4' in str(b)
    params['sigma_um'] = 0.2
    params.update()
    v2 = to_np(b.eval(ctx, si, wo))
    assert not np.allclose(v1, v2)
    params['sigma_um'] = -1.0
    with pytest.raises(Exception, match='sigma_um'):
        params.update()


# ---------------------------------------------------------------------------
# Rendering
# ---------------------------------------------------------------------------

def scene_dict(surface='gaussian', **extra):
    return {
        'type': 'scene',
        'integrator': {'type': 'path', 'max_depth': 3},
        'sensor': {'type': 'perspective', 'fov': 40,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -3, 2],
                                                              target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': 24, 'height': 16,
                            'rfilter': {'type': 'box'}},
                   'sampler': {'type': 'independent', 'sample_count': 16}},
        'plane': {'type': 'rectangle', 'bsdf': bsdf_dict(surface, **extra)},
        'light': {'type': 'point', 'position': [0, 2.5, 2.0],
                  'intensity': {'type': 'spectrum', 'value': 10.0}},
        'env': {'type': 'constant', 'radiance': {'type': 'spectrum', 'value': 0.2}},
    }


@pytest.mark.parametrize('variant', ALL_VARIANTS)
@pytest.mark.parametrize('surface', ['gaussian', 'cd'])
def test17_small_scene_finite(variant, surface):
    use(variant)
    extra = {'tracks': 'concentric'} if surface == 'cd' else {}
    img = to_np(mi.render(mi.load_dict(scene_dict(surface, **extra)), spp=8))
    assert np.all(np.isfinite(img))
    assert img.mean() > 0


def test18_compact_disc_with_default_flags():
    """The compact disc (periodic model) in llvm_ad_rgb with Dr.Jit's default
    flags (the plugin runs the core's programs: tests/test_jit.py): the
    symbolic render equals the evaluated-mode one."""
    use('llvm_ad_rgb')
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)
    scene = mi.load_dict(scene_dict('cd', tracks='concentric'))
    img = to_np(mi.render(scene, spp=4, seed=5))
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False), \
            dr.scoped_set_flag(dr.JitFlag.SymbolicCalls, False):
        ref = to_np(mi.render(scene, spp=4, seed=5))
    assert np.all(np.isfinite(img)) and img.mean() > 0
    assert np.allclose(img, ref, rtol=1e-3, atol=1e-5 * ref.max())


def test19_scalar_vs_llvm():
    means = {}
    for v in ('scalar_rgb', 'llvm_ad_rgb'):
        use(v)
        # Point light only: no Monte Carlo noise beyond pixel jitter, so the
        # two code paths of the plugin (scalar, batched JIT) must agree.
        scene = scene_dict('gaussian')
        del scene['env']
        scene['integrator'] = {'type': 'direct'}
        img = to_np(mi.render(mi.load_dict(scene), spp=1024, seed=1))
        means[v] = img.reshape(4, 4, 6, 4, 3).mean(axis=(1, 3))   # 4x6 blocks
    a, b = means['scalar_rgb'], means['llvm_ad_rgb']
    assert np.allclose(a.mean(), b.mean(), rtol=0.005)
    assert np.allclose(a, b, rtol=0.1, atol=0.02 * a.mean())
