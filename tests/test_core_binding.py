"""Tests of stam_diffraction.core (python/), the ctypes binding of the core's C ABI
(target/release/libstam.so, `make core`), each method against something
independent of it: closed forms (a flat spectrum, the coherent lobe's
F^2 exp(-g)), another entry point of the ABI, Monte Carlo integrals against
quadrature. Also: every material of the shared list tests/materials.json is
accepted by the core.
"""

import math
import os
import re
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
sys.path.insert(0, os.path.join(ROOT, 'python'))
import stam_materials  # noqa: E402
from stam_diffraction import core as stam_core  # noqa: E402

# Spectrally flat: a fractal with H = 1 scatters the same at every wavelength,
# and a constant Fresnel reflectance keeps it so.
FLAT = {'surface': 'fractal', 'sigma_um': 0.1, 'hurst': 1.0, 'lag_um': 1.0, 'fresnel': 0.5}
GAUSSIAN = {'surface': 'gaussian', 'sigma_um': 0.05, 'corr_um': 2.0, 'fresnel': 0.5}
# Both lobes: about 16 % of the samples go to the coherent lobe at WI
MIXED = {'surface': 'gaussian', 'sigma_um': 0.06, 'corr_um': 0.6, 'fresnel': 0.5}
GRATING = {'surface': 'periodic', 'period_um': 1.6, 'profile': 'sine', 'height_um': 0.25,
           'coherence_um': 8.0}
WI = np.array([0.3, 0.1, math.sqrt(0.9)])


def hemisphere(n, seed=1):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=1)[:, None]


def quadrature(n_theta=200, n_phi=400):
    """Midpoint directions over the hemisphere and their solid angles."""
    t = (np.arange(n_theta) + 0.5) * (0.5 * math.pi / n_theta)
    p = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)
    T, P = np.meshgrid(t, p, indexing='ij')
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    dw = np.sin(T) * (0.5 * math.pi / n_theta) * (2 * math.pi / n_phi)
    return d.reshape(-1, 3), dw.reshape(-1)


def test_version_is_the_crate_version():
    with open(os.path.join(ROOT, 'rust-core', 'Cargo.toml')) as f:
        crate = re.search(r'^version\s*=\s*"([^"]+)"', f.read(), re.M).group(1)
    assert stam_core.version() == crate


def test_luminance_weights_are_srgb():
    # The Y row of the sRGB -> XYZ matrix (IEC 61966-2-1): a flat spectrum
    # maps to RGB (1, 1, 1) of luminance 1.
    assert np.allclose(stam_core.SRGB_LUMINANCE, [0.2126, 0.7152, 0.0722], atol=1e-4)
    assert abs(stam_core.SRGB_LUMINANCE.sum() - 1.0) < 1e-6


def test_eval_rgb_of_a_flat_spectrum_is_grey_and_equals_eval_spectral():
    wo = hemisphere(64)
    with stam_core.Brdf(FLAT) as b:
        rgb = b.eval_rgb(WI, wo)
        assert rgb.shape == (64, 3)
        spec = np.stack([b.eval_spectral(WI, wo, lam) for lam in (400.0, 550.0, 700.0)])
    assert np.all(spec > 0)
    assert np.allclose(spec, spec[1], rtol=1e-5)
    for c in range(3):
        assert np.allclose(rgb[:, c], spec[1], rtol=1e-3)


def test_eval_spectral_broadcasts_like_per_element_calls():
    wo = hemisphere(8)
    lams = np.array([450.0, 520.0, 590.0, 660.0])
    with stam_core.Brdf(GRATING) as b:
        table = b.eval_spectral(WI, wo[:, None, :], lams)          # (8, 4)
        assert table.shape == (8, 4)
        for i in range(8):
            for j, lam in enumerate(lams):
                assert table[i, j] == b.eval_spectral(WI, wo[i], lam)
        assert b.eval_spectral(WI, wo[0], 500.0).shape == ()
        # Out-of-contract inputs give finite, non-negative zeros (stam.h)
        bad = b.eval_spectral([0, 0, np.nan], wo[0], [np.nan, 0.0, -5.0])
        assert np.all(np.isfinite(bad)) and np.all(bad >= 0)


def test_eval_rgb_of_a_grating_is_in_gamut():
    with stam_core.Brdf(GRATING) as b:
        rgb = b.eval_rgb(WI, hemisphere(400, seed=2))
    assert np.all(rgb >= 0) and rgb.max() > 0


def test_coherent_spectral_is_f2_exp_minus_g():
    """Stam's coherent lobe: F^2 exp(-g), g = (4 pi sigma cos(theta_i) / lambda)^2."""
    lam = np.array([400.0, 550.0, 700.0])
    with stam_core.Brdf(GRATING) as b:
        assert np.all(b.coherent_spectral(WI, lam) == 0)
        assert np.all(b.coherent_rgb(WI) == 0)
    with stam_core.Brdf(GAUSSIAN) as b:
        for th in (0.0, 0.5, 1.2):
            wi = np.array([math.sin(th), 0.0, math.cos(th)])
            g = (4 * math.pi * GAUSSIAN['sigma_um'] * math.cos(th) / (lam * 1e-3)) ** 2
            assert np.allclose(b.coherent_spectral(wi, lam), 0.5 * np.exp(-g), rtol=1e-5)
            assert b.coherent_spectral(wi[None], lam).shape == (3,)


def test_coherent_rgb_of_a_mirror_is_the_reflectance():
    smooth = dict(GAUSSIAN, sigma_um=1e-6)      # g ~ 1e-9: a perfect mirror
    with stam_core.Brdf(smooth) as b:
        assert np.allclose(b.coherent_rgb(np.stack([WI, [0, 0, 1.0]])), 0.5, rtol=1e-5)
    with stam_core.Brdf(GAUSSIAN) as b:
        # Blue loses more to exp(-g) than red
        r, g, bl = b.coherent_rgb(WI)
        assert 0 < bl < g < r < 0.5


def test_flags():
    F = stam_core
    with F.Brdf(GAUSSIAN) as b:
        assert b.flags() & F.FLAG_HAS_COHERENT
        assert not b.flags() & F.FLAG_ANISOTROPIC
    with F.Brdf({'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 1.0,
                 'corr_y_um': 4.0}) as b:
        assert b.flags() & F.FLAG_ANISOTROPIC
    with F.Brdf(GRATING) as b:
        assert b.flags() & F.FLAG_ANISOTROPIC and b.flags() & F.FLAG_SPECTRALLY_VARYING
        assert not b.flags() & F.FLAG_HAS_COHERENT
    with F.Brdf(FLAT) as b:
        assert not b.flags() & (F.FLAG_HAS_COHERENT | F.FLAG_ANISOTROPIC)


def test_memory_bytes_counts_the_rgb_table_once_built():
    with stam_core.Brdf(GAUSSIAN) as b:
        before = b.memory_bytes()
        assert before > 0
        b.eval_rgb(WI, [-WI[0], -WI[1], WI[2]])
        assert b.memory_bytes() > before


@pytest.mark.parametrize('params', [FLAT, GAUSSIAN, GRATING], ids=['flat', 'gaussian', 'grating'])
@pytest.mark.parametrize('lam', [None, 550.0], ids=['rgb', 'spectral'])
def test_sample_pdf_equals_pdf_at_the_sampled_direction(params, lam):
    rnd = np.random.default_rng(5).random((2000, 3))
    with stam_core.Brdf(params) as b:
        wo, pdf, coh = b.sample(WI, rnd, lam)
        assert wo.shape == (2000, 3) and pdf.shape == (2000,) and coh.dtype == bool
        glossy = ~coh & (pdf > 0)
        assert glossy.sum() > 1000
        assert np.allclose(np.linalg.norm(wo[glossy], axis=1), 1.0, atol=1e-5)
        assert np.all(wo[glossy, 2] >= 0)
        assert np.allclose(b.pdf(WI, wo[glossy], lam), pdf[glossy], rtol=1e-5)
        if coh.any():
            assert np.allclose(wo[coh], [-WI[0], -WI[1], WI[2]], atol=1e-5)
            assert np.allclose(pdf[coh], b.coherent_probability(WI, lam), rtol=1e-6)


@pytest.mark.parametrize('lam', [None, 550.0], ids=['rgb', 'spectral'])
def test_sampled_density_integrates_like_pdf(lam):
    """E[1{glossy} cos / pdf] = the integral of cos over the hemisphere = pi
    (the glossy density is positive everywhere above the horizon), whatever
    share the coherent lobe takes; and that share matches
    coherent_probability."""
    n = 200000
    rnd = np.random.default_rng(6).random((n, 3))
    with stam_core.Brdf(MIXED) as b:
        wo, pdf, coh = b.sample(WI, rnd, lam)
        pc = float(b.coherent_probability(WI, lam))
    assert 0.1 < pc < 0.3
    glossy = ~coh & (pdf > 0)
    est = np.where(glossy, wo[:, 2] / np.where(glossy, pdf, 1.0), 0.0)
    err = 4 * est.std() / math.sqrt(n)
    assert abs(est.mean() - math.pi) < err + 0.01 * math.pi, (est.mean(), err)
    share = coh.mean()
    assert abs(share - pc) < 4 * math.sqrt(pc * (1 - pc) / n) + 1e-3


def test_sampling_estimates_the_albedo_found_by_quadrature():
    """E[f cos / pdf] (glossy) + E[coherent / P] (coherent) = the directional
    albedo: integral of f cos by quadrature plus the coherent reflectance."""
    lam = 550.0
    d, dw = quadrature()
    n = 40000
    rnd = np.random.default_rng(7).random((n, 3))
    with stam_core.Brdf(MIXED) as b:
        albedo = float((b.eval_spectral(WI, d, lam) * d[:, 2] * dw).sum()
                       + b.coherent_spectral(WI, lam))
        wo, pdf, coh = b.sample(WI, rnd, lam)
        f = b.eval_spectral(WI, wo, lam)
        c = b.coherent_spectral(WI, lam)
    ok = pdf > 0
    w = np.zeros(n)
    g = ok & ~coh
    w[g] = f[g] * wo[g, 2] / pdf[g]
    w[ok & coh] = c / pdf[ok & coh]
    err = 4 * w.std() / math.sqrt(n)
    assert 0.4 < albedo < 0.6     # about F^2 = 0.5
    assert abs(w.mean() - albedo) < err + 0.01 * albedo, (w.mean(), albedo, err)


def test_coherent_probability():
    wi = np.stack([WI, [0, 0, 1.0], [math.sqrt(1 - 0.05 ** 2), 0, 0.05]])
    with stam_core.Brdf(GAUSSIAN) as b:
        p = b.coherent_probability(wi)
        assert p.shape == (3,) and np.all((p > 0) & (p <= 1))
        assert b.coherent_probability(wi, [450.0, 550.0, 650.0]).shape == (3,)
    with stam_core.Brdf(GRATING) as b:
        assert np.all(b.coherent_probability(wi) == 0)


@pytest.mark.parametrize('lam', [None, [450.0, 520.0, 590.0, 660.0]], ids=['rgb', 'spectral'])
def test_vertex_queries_agree_with_the_plain_calls(lam):
    n = 300
    wo_in = hemisphere(n, seed=8)
    rnd = np.random.default_rng(9).random((n, 3))
    lanes = None if lam is None else np.tile(lam, (n, 1))
    with stam_core.Brdf(GAUSSIAN) as b:
        f, pdf = b.eval_pdf_vertex(WI, wo_in, lanes)
        if lam is None:
            assert f.shape == (n, 3)
            assert np.allclose(f, b.eval_rgb(WI, wo_in), rtol=1e-5, atol=1e-30)
            assert np.allclose(pdf, b.pdf(WI, wo_in), rtol=1e-5)
        else:
            assert f.shape == (n, 4)
            for j, l in enumerate(lam):
                assert np.allclose(f[:, j], b.eval_spectral(WI, wo_in, l), rtol=1e-5,
                                   atol=1e-30)
            # the one-sample mixture over the path's wavelengths (stam.h)
            mix = np.mean([b.pdf(WI, wo_in, l) for l in lam], axis=0)
            assert np.allclose(pdf, mix, rtol=1e-4)
        wo, spdf, coh, value = b.sample_vertex(WI, rnd, lanes)
        g = ~coh & (spdf > 0)
        assert g.sum() > n // 2
        f2, pdf2 = b.eval_pdf_vertex(WI, wo[g], None if lanes is None else lanes[g])
        assert np.allclose(spdf[g], pdf2, rtol=1e-4)
        assert np.allclose(value[g], f2, rtol=1e-4, atol=1e-30)
        if lam is None:
            # RGB vertex sampling is stam_brdf_sample's RGB mode
            wo_s, pdf_s, coh_s = b.sample(WI, rnd)
            assert np.array_equal(coh_s, coh) and np.allclose(wo_s, wo) and \
                np.allclose(pdf_s, spdf)
        both = b.eval_pdf_sample_vertex(WI, wo_in, rnd, lanes)
        for x, y in zip(both, (f, pdf, wo, spdf, coh, value)):
            assert np.array_equal(x, y)


@pytest.mark.parametrize('params,key', [
    ({'surface': 'banana'}, 'surface'),
    (dict(GAUSSIAN, sigma_um=-1.0), 'sigma_um'),
    (dict(GAUSSIAN, sigmaa_um=0.1), 'sigmaa_um'),
    ({'surface': 'fractal', 'sigma_um': 0.1, 'lag_um': 1.0, 'hurst': 1.5}, 'hurst'),
    (dict(GRATING, period_um=0.0), 'period_um'),
])
def test_bad_params_raise_value_error_naming_the_key(params, key):
    with pytest.raises(ValueError, match=key):
        stam_core.Brdf(params)


def test_params_as_json_text():
    with pytest.raises(ValueError, match='JSON'):
        stam_core.Brdf('{"surface": ')
    with stam_core.Brdf('{"surface": "cd"}') as b:
        assert b.params_json == '{"surface": "cd"}'


def test_close_is_idempotent_and_use_after_close_refused():
    b = stam_core.Brdf(GAUSSIAN)
    with b:
        pass
    b.close()
    assert 'closed' in repr(b)
    with pytest.raises(ValueError, match='closed'):
        b.eval_rgb(WI, WI)
    del b      # __del__ after close: no double free


def test_library_path_from_environment(monkeypatch):
    monkeypatch.setattr(stam_core, '_lib', None)
    monkeypatch.setenv('STAM_CORE_LIB', os.path.join(ROOT, 'no-such-libstam.so'))
    with pytest.raises(FileNotFoundError, match='no-such-libstam'):
        stam_core.Brdf(GAUSSIAN)


def test_shared_materials_are_accepted_and_named_uniquely():
    entries = stam_materials.load()
    names = [e['name'] for e in entries]
    assert len(names) == len(set(names))
    tags = {t for e in entries for t in e['tags']}
    for t in tags:
        stam_materials.by_label(t)    # raises on a label used twice in a tag
    for e in entries:
        assert e['model'] in ('gaussian', 'fractal', 'periodic'), e['name']
        surface = e['params']['surface']
        assert e['model'] == ('periodic' if surface == 'cd' else surface), e['name']
        with stam_core.Brdf(e['params']) as b:
            assert b.memory_bytes() > 0


def test_warnings_name_implausible_values():
    """stam_brdf_warnings: a unit mistake (sigma in nanometres) is named,
    a plausible material has none."""
    with stam_core.Brdf({'surface': 'gaussian', 'sigma_um': 100, 'corr_um': 1000}) as b:
        w = b.warnings()
        assert len(w) == 1 and "'sigma_um'" in w[0] and 'nanometres' in w[0], w
    with stam_core.Brdf({'surface': 'cd'}) as b:
        assert b.warnings() == []


def test_export_table_is_the_gaussian_rule_data():
    """stam_brdf_export_table (docs/jit.md): Gaussian materials export the
    "gaussian-v1" data (header, the Fresnel grid of a constant reflectance);
    other models and "energy": "conserving" have none. The rule itself is
    checked against the core in rust-core/tests/jit_export.rs and by
    scripts/jit_prototype.py accuracy."""
    with stam_core.Brdf(GAUSSIAN) as b:
        e = b.export_table()
    assert e is not None and e.dtype == np.float32
    assert (e[0], e[1], e[2]) == (1.0, 1.0, 32.0) and int(e[3]) == len(e)
    assert np.all(np.isfinite(e))
    assert (e[4], e[5], e[6]) == (np.float32(0.05), np.float32(2.0), np.float32(2.0))
    # Fresnel rows of F^2 = 0.5: every value 0.5.
    rows, cols = int(e[19]), int(e[20]) + 1
    fresnel = e[int(e[18]):int(e[18]) + rows * cols]
    assert np.all(fresnel == np.float32(0.5))
    for params in (FLAT, GRATING, dict(GAUSSIAN, energy='conserving')):
        with stam_core.Brdf(params) as b:
            assert b.export_table() is None
