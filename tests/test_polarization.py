"""Polarised variants (docs/polarisation.md): in scalar_spectral_polarized the
`diffraction` BSDF returns a Mueller matrix, the core's polarisation of the
reflection (stam_brdf_polarization: the Fresnel reflection's at the pair's half
vector, for every surface whose value is F^2 G K; for rigorous gratings each
order's from the solver's amplitudes, stam_brdf_mueller) times the unpolarised
value, its Stokes bases rotated as Mitsuba's roughconductor rotates its own.

Run: make core plugin && .venv/bin/python -m pytest tests/test_polarization.py
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

VARIANT = 'scalar_spectral_polarized'
WAVELENGTHS = [450.0, 520.0, 590.0, 660.0]
# A metal's constant complex index (aluminium near 650 nm), which Mitsuba's
# roughconductor takes too.
ETA, K = 1.2, 6.9

# Every surface model's plugin material, the compact disc ('cd') among them.
SURFACES = stam_materials.by_label('plugin')


def use(variant=VARIANT):
    return stam_mitsuba.setup(variant)


def direction(theta, phi):
    return [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]


def interaction(wi):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.3, 0.7)
    si.wavelengths = mi.UnpolarizedSpectrum(WAVELENGTHS)
    return si


def mueller(spectrum):
    """A scalar_spectral_polarized Spectrum as an array (wavelength, 4, 4)."""
    return np.moveaxis(np.array(spectrum, dtype=np.float64), -1, 0)


def pairs(rng, count, max_theta=1.2):
    return [(direction(rng.uniform(0, max_theta), rng.uniform(0, 2 * math.pi)),
             direction(rng.uniform(0, max_theta), rng.uniform(0, 2 * math.pi)))
            for _ in range(count)]


def test_mueller_matrix_is_roughconductors_in_the_beckmann_limit():
    """A rough Gaussian surface (sigma / T = 1/8: Beckmann with alpha = 2 sigma
    / T) against roughconductor (Beckmann, the same index) at directions
    sampled from roughconductor's lobe: the Mueller matrices over their [0][0]
    agree within 1e-4 per element (the same Fresnel reflection at the same
    half vector, in the same bases); [0][0] itself, the unpolarised models',
    within 1% at the median and 90% of the pairs."""
    use()
    sigma, corr = 1.0, 8.0
    ours = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': sigma,
                         'corr_um': corr, 'eta': ETA, 'k': K, 'energy': 'stam'})
    beckmann = mi.load_dict({'type': 'roughconductor', 'distribution': 'beckmann',
                             'alpha': 2 * sigma / corr, 'eta': ETA, 'k': K})
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(7)
    worst, ratios = 0.0, []
    while len(ratios) < 150:
        si = interaction(direction(rng.uniform(0, 1.0), rng.uniform(0, 2 * math.pi)))
        bs, _ = beckmann.sample(ctx, si, rng.uniform(), mi.Point2f(rng.uniform(), rng.uniform()))
        if not bs.wo[2] > 0.17:
            continue
        a = mueller(ours.eval(ctx, si, bs.wo))
        b = mueller(beckmann.eval(ctx, si, bs.wo))
        if not (a[:, 0, 0] > 0).all():
            continue
        worst = max(worst, np.abs(a / a[:, :1, :1] - b / b[:, :1, :1]).max())
        ratios.extend(a[:, 0, 0] / b[:, 0, 0])
    off = np.abs(np.array(ratios) - 1)
    print('normalised elements: worst %.2e; [0][0] ratio - 1: median %.4f, p90 %.4f, max %.4f'
          % (worst, np.median(off), np.percentile(off, 90), off.max()))
    assert worst < 1e-4
    assert np.median(off) < 0.01 and np.percentile(off, 90) < 0.01


@pytest.mark.parametrize('surface', sorted(SURFACES))
def test_m00_is_the_unpolarized_value(surface):
    """[0][0] of eval, and of a sample's weight, is scalar_spectral's value
    (the same core calls), within 1e-6 relative, at random pairs and
    samples; a sample's direction and pdf are the same."""
    params = dict({'type': 'diffraction'}, **stam_materials.plugin_params(SURFACES[surface]))
    rng = np.random.default_rng(3)
    cases = pairs(rng, 40, 1.3)
    rnd = [(rng.uniform(), (rng.uniform(), rng.uniform())) for _ in cases]
    out = {}
    for variant in ('scalar_spectral', VARIANT):
        use(variant)
        bsdf = mi.load_dict(params)
        ctx = mi.BSDFContext()
        values = []
        for (wi, wo), (s1, s2) in zip(cases, rnd):
            si = interaction(wi)
            f = np.array(bsdf.eval(ctx, si, mi.Vector3f(wo)), dtype=np.float64)
            bs, w = bsdf.sample(ctx, si, s1, mi.Point2f(s2))
            w = np.array(w, dtype=np.float64)
            if variant == VARIANT:
                f, w = mueller(f)[:, 0, 0], mueller(w)[:, 0, 0]
            values.append((f, w, np.array(bs.wo), bs.pdf))
        out[variant] = values
    for a, b in zip(out['scalar_spectral'], out[VARIANT]):
        for x, y in zip(a, b):
            assert np.allclose(x, y, rtol=1e-6, atol=1e-30), (surface, x, y)


def coherency_eigenvalues(m):
    """Eigenvalues of the Cloude coherency matrix of the Mueller matrix m (4x4):
    all >= 0 for a physically realisable one (a sum of pure, non-depolarising
    elements)."""
    paulis = [np.eye(2), np.array([[1, 0], [0, -1]]), np.array([[0, 1], [1, 0]]),
              np.array([[0, -1j], [1j, 0]])]
    h = sum(m[i, j] * np.kron(paulis[i], paulis[j].conj()) for i in range(4) for j in range(4))
    return np.linalg.eigvalsh(h / 4)


@pytest.mark.parametrize('surface', sorted(SURFACES))
def test_mueller_matrices_are_physical(surface):
    """At random pairs and sampled ones: finite; physically realisable (no coherency matrix
    eigenvalue below -1e-6 of [0][0]); unpolarised light leaves with a degree
    of polarisation at most 1; and, a reflection at one facet not
    depolarising, polarised light leaves fully polarised (degree 1 within
    1e-4)."""
    use()
    params = dict({'type': 'diffraction'}, **stam_materials.plugin_params(SURFACES[surface]))
    bsdf = mi.load_dict(params)
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(11)
    seen = 0
    for wi, wo in pairs(rng, 60, 1.4):
        # Half at random, half sampled by the material (into its lobes: a
        # grating's orders are narrow)
        si = interaction(wi)
        bs, _ = bsdf.sample(ctx, si, rng.uniform(), mi.Point2f(rng.uniform(), rng.uniform()))
        for m in np.concatenate([mueller(bsdf.eval(ctx, si, mi.Vector3f(wo))),
                                 mueller(bsdf.eval(ctx, si, bs.wo))]):
            assert np.isfinite(m).all()
            # (Values in f32's subnormal range keep too few digits to test.)
            if not m[0, 0] > 1e-30:
                continue
            seen += 1
            assert coherency_eigenvalues(m).min() >= -1e-6 * m[0, 0], m
            out = m @ [1, 0, 0, 0]
            assert np.linalg.norm(out[1:]) <= out[0] * (1 + 1e-6)
            for stokes in ([1, 1, 0, 0], [1, 0, 0, 1], [1, 0, -1, 0]):
                out = m @ np.array(stokes, dtype=np.float64)
                assert abs(np.linalg.norm(out[1:]) / out[0] - 1) < 1e-4
    assert seen > 20


def test_a_metal_polarizes_as_fresnel_predicts():
    """Unpolarised light on a smooth metal near grazing (80 degrees, the
    mirror pair): the reflected light's degree of linear polarisation is
    Fresnel's, (|r_s|^2 - |r_p|^2) / (|r_s|^2 + |r_p|^2), from the complex
    amplitudes written here, within 1e-4; partly polarised (over 0.1), and
    less so at normal incidence (below 1e-3)."""
    use()
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.02,
                         'corr_um': 2.0, 'eta': ETA, 'k': K, 'energy': 'stam'})
    ctx = mi.BSDFContext()
    n = complex(ETA, K)
    for theta, bound in ((math.radians(80), None), (0.02, 1e-3)):
        wi = direction(theta, 0.4)
        wo = [-wi[0], -wi[1], wi[2]]
        c = math.cos(theta)
        w = np.sqrt(n * n - (1 - c * c))
        rs2 = abs((c - w) / (c + w)) ** 2
        rp2 = abs((n * n * c - w) / (n * n * c + w)) ** 2
        want = (rs2 - rp2) / (rs2 + rp2)
        for m in mueller(bsdf.eval(ctx, interaction(wi), mi.Vector3f(wo))):
            dolp = math.hypot(m[1, 0], m[2, 0]) / m[0, 0]
            assert abs(dolp - want) < 1e-4, (theta, dolp, want)
            if bound is None:
                assert dolp > 0.1
            else:
                assert dolp < bound


RIGOROUS = {'surface': 'periodic', 'profile': 'rect', 'period_um': 1.6, 'height_um': 0.1,
            'width_um': 0.8, 'coherence_um': 10.0, 'orders': 'rigorous'}


def on_order(wi, n, lambda_nm, period_um, dv=0.0):
    """The direction of order n of a grating across x for light from wi
    (u = -(wi.x + wo.x) = n lambda / period), moved by dv off the mirror in y."""
    x = -wi[0] + n * lambda_nm * 1e-3 / period_um
    y = -wi[1] + dv
    return [x, y, math.sqrt(max(1 - x * x - y * y, 0.0))]


def test_rigorous_gratings_give_each_orders_mueller_matrix():
    """Rigorous gratings in scalar_spectral_polarized: the plugin's matrix is
    the core's (stam_brdf_mueller: each order's from the solver's complex
    amplitudes, in bases tied to the grooves) times the unpolarised value,
    rotated into Mitsuba's bases by Mitsuba's own rotate_mueller_basis; its
    [0][0] is scalar_spectral's value; in conical incidence the orders
    polarise (the cross blocks are not zero). JIT variants still depolarize
    them, and a grating with a cover has no matrix (documented)."""
    params = dict(RIGOROUS, fresnel={'eta': ETA, 'k': K})
    core = stam_core.Brdf(params)
    assert core.polarization([0, 0, 1], [0.3, 0, 0.95], 550.0) is None
    plugin = dict(RIGOROUS, type='diffraction', eta=ETA, k=K)
    use('scalar_spectral')
    plain = mi.load_dict(plugin)
    use()
    bsdf = mi.load_dict(plugin)
    ctx = mi.BSDFContext()
    checked, polarising = 0, 0
    for theta, phi, n in [(0.5, 0.3, 1), (0.3, 1.2, -1), (0.7, 2.5, 2), (0.2, 0.0, 1)]:
        wi = direction(theta, phi)
        for dv in (0.0, 0.004):
            wo = on_order(wi, n, 550.0, RIGOROUS['period_um'], dv)
            got = mueller(bsdf.eval(ctx, interaction(wi), mi.Vector3f(wo)))
            use('scalar_spectral')
            value = np.array(plain.eval(ctx, interaction(wi), mi.Vector3f(wo)), dtype=np.float64)
            use()
            # Radiance mode: the light arrives from wo and leaves along wi.
            m, s_in, s_out = core.mueller(wo, wi, np.array(WAVELENGTHS))
            for j, lam in enumerate(WAVELENGTHS):
                assert abs(got[j][0, 0] - value[j]) <= 1e-6 * max(value[j], 1e-30)
                if value[j] < 1e-6:
                    continue
                want = mi.mueller.rotate_mueller_basis(
                    mi.Matrix4f((m[j] * value[j]).tolist()),
                    -mi.Vector3f(wo), mi.Vector3f(s_in[j]), mi.mueller.stokes_basis(-mi.Vector3f(wo)),
                    mi.Vector3f(wi), mi.Vector3f(s_out[j]), mi.mueller.stokes_basis(mi.Vector3f(wi)))
                want = np.array(want, dtype=np.float64)
                assert np.allclose(got[j], want, atol=1e-5 * value[j]), (got[j], want)
                checked += 1
                polarising += np.abs(got[j][:2, 2:]).max() > 1e-3 * value[j]
    assert checked >= 8 and polarising > 0, (checked, polarising)
    # JIT variants depolarize rigorous gratings (no program for the table yet).
    use('llvm_ad_spectral_polarized')
    jit = mi.load_dict(plugin)
    wi = direction(0.5, 0.3)
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.3, 0.7)
    si.wavelengths = mi.UnpolarizedSpectrum(WAVELENGTHS)
    m = np.array(jit.eval(ctx, si, mi.Vector3f(on_order(wi, 1, 550.0, 1.6))), dtype=np.float64)
    m = m.reshape(4, 4, -1)
    assert (m[0, 0] > 0).any() and np.abs(m[1:, :]).max() == 0 and np.abs(m[:, 1:]).max() == 0
    covered = stam_core.Brdf(dict(params, cover_eta=1.5))
    assert covered.mueller([0, 0, 1], [0.3, 0, 0.95], 550.0) is None


@pytest.mark.parametrize('variant', [VARIANT, 'llvm_ad_spectral_polarized'])
def test_stokes_render_of_a_metal_sphere(variant):
    """The `stokes` integrator's render of a smooth metal sphere under an
    unpolarised point light: finite, S0 > 0 on the sphere, the reflected
    light partly polarised (some pixel with S1 or S2 over 1% of S0) and no
    pixel more than fully polarised; in the scalar variant and in the JIT
    one (its symbolic loops and calls)."""
    use(variant)
    scene = mi.load_dict({
        'type': 'scene',
        'integrator': {'type': 'stokes', 'integrator': {'type': 'path', 'max_depth': 2}},
        'sensor': {'type': 'perspective', 'fov': 30,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -4, 1.5], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': 16, 'height': 16,
                            'pixel_format': 'rgb'},
                   'sampler': {'type': 'independent', 'sample_count': 4}},
        'sphere': {'type': 'sphere', 'bsdf': {'type': 'diffraction', 'surface': 'gaussian',
                                              'sigma_um': 0.05, 'corr_um': 1.0, 'eta': ETA,
                                              'k': K}},
        'light': {'type': 'point', 'position': [3, -3, 3],
                  'intensity': {'type': 'spectrum', 'value': 30.0}},
    })
    img = np.array(mi.render(scene), dtype=np.float64)
    # Channels: the image, then S0..S3, three (RGB) each; each component's
    # luminance (a projection of the spectrum with non-negative weights, so
    # that |S1|, |S2|, |S3| <= S0 holds for it as for each wavelength)
    s = img[..., 3:].reshape(img.shape[:2] + (4, 3)) @ np.array([0.2126, 0.7152, 0.0722])
    assert np.isfinite(s).all()
    lit = s[:, :, 0] > 1e-4
    assert lit.sum() > 4
    dop = np.linalg.norm(s[:, :, 1:], axis=-1)
    assert (dop[lit] <= s[:, :, 0][lit] * (1 + 1e-3)).all()
    lin = np.hypot(s[:, :, 1], s[:, :, 2])
    assert (lin[lit] > 0.01 * s[:, :, 0][lit]).any()


def jit_eval(variant, params, cases):
    """eval at the pairs `cases` in one call of a JIT variant: an array
    (pair, wavelength, 4, 4) of Mueller matrices (polarized variants) or
    (pair, wavelength) of values."""
    use(variant)
    bsdf = mi.load_dict(params)
    n = len(cases)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    wi = np.array([c[0] for c in cases], dtype=np.float32)
    wo = np.array([c[1] for c in cases], dtype=np.float32)
    si.wi = mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.3, 0.7)
    if 'spectral' in variant:
        si.wavelengths = mi.UnpolarizedSpectrum(*[dr.full(mi.Float, lam, n) for lam in WAVELENGTHS])
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2]))
    a = np.array(value, dtype=np.float64)
    if 'polarized' in variant:
        # (row, column, wavelength, lane) -> (lane, wavelength, row, column)
        return np.transpose(a, (3, 2, 0, 1))
    return a.T


JIT_MATERIALS = {
    'gaussian_index': {'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.3,
                       'corr_um': 3.0, 'eta': ETA, 'k': K},
    'fractal_gold': {'type': 'diffraction', 'surface': 'fractal', 'sigma_um': 0.05, 'hurst': 0.7,
                     'lag_um': 1.0, 'fresnel': 'gold'},
    'cd': {'type': 'diffraction', 'surface': 'cd'},
}


@pytest.mark.parametrize('name', sorted(JIT_MATERIALS))
def test_jit_polarized_variant_follows_the_scalar_one(name):
    """llvm_ad_spectral_polarized runs the core's polarisation program: its
    matrices over their [0][0] equal scalar_spectral_polarized's within 2e-3
    per element (a metal's index read from whole nanometres, f32), and its
    [0][0] is llvm_ad_spectral's value within 1e-5 relative; llvm_ad_mono_polarized
    renders the same way (finite, [0][0] llvm_ad_mono's)."""
    params = JIT_MATERIALS[name]
    rng = np.random.default_rng(5)
    cases = pairs(rng, 64, 1.3)
    # As many again sampled by the material (a grating's orders are narrow)
    use()
    bsdf = mi.load_dict(params)
    ctx = mi.BSDFContext()
    for wi, _ in cases[:64]:
        bs, _ = bsdf.sample(ctx, interaction(wi), rng.uniform(),
                            mi.Point2f(rng.uniform(), rng.uniform()))
        cases.append((wi, list(np.array(bs.wo, dtype=np.float64))))
    scalar = np.array([mueller(bsdf.eval(ctx, interaction(wi), mi.Vector3f(wo)))
                       for wi, wo in cases])
    jit = jit_eval('llvm_ad_spectral_polarized', params, cases)
    plain = jit_eval('llvm_ad_spectral', params, cases)
    assert np.isfinite(jit).all()
    m00 = jit[..., 0, 0]
    assert np.allclose(m00, plain, rtol=1e-5, atol=1e-30)
    lit = (m00 > 1e-20) & (scalar[..., 0, 0] > 1e-20)
    assert lit.sum() > 40
    worst = np.abs(jit[lit] / m00[lit][:, None, None]
                   - scalar[lit] / scalar[lit][:, :1, :1]).max()
    print('%s: worst normalised element, llvm_ad_spectral_polarized - scalar: %.1e' % (name, worst))
    assert worst < 2e-3
    mono = jit_eval('llvm_ad_mono_polarized', params, cases)
    mono_plain = jit_eval('llvm_ad_mono', params, cases)
    assert np.isfinite(mono).all()
    assert np.allclose(mono[..., 0, 0], mono_plain, rtol=1e-5, atol=1e-30)
