"""Texturable parameters of the `diffraction` BSDF (issue 14): a twist map
and a sigma map.

`twist` takes any Mitsuba texture (degrees, unbounded): the tracks turn by
the texture's value at each point, in every variant. `sigma_um` of a Gaussian
surface takes one in the JIT variants (the programs read sigma per point,
built for every sigma up to the texture's largest value). Other parameters
refuse a texture with a message naming them. In the AD variants the
texture's values are differentiable (mi.traverse: twist.<its parameters>,
sigma_um.<its parameters>).

Run: make core plugin && .venv/bin/python -m pytest tests/test_textures.py
"""

import math
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import stam_mitsuba  # noqa: E402

import drjit as dr  # noqa: E402

VARIANTS = ['scalar_rgb', 'scalar_spectral', 'llvm_ad_rgb', 'llvm_ad_spectral']
BRUSHED = {'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 1.0,
           'corr_y_um': 3.0}


WAVELENGTHS = [450.0, 520.0, 590.0, 660.0]   # a spectral path's, in these tests


def eval_at(mi, bsdf, uv, wo=(-0.1, -0.5)):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(0.3, 0.2, math.sqrt(1 - 0.13))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    si.uv = mi.Point2f(*uv)
    if mi.is_spectral:
        si.wavelengths = WAVELENGTHS
    wo = mi.Vector3f(wo[0], wo[1], math.sqrt(1 - wo[0] ** 2 - wo[1] ** 2))
    return np.array(bsdf.eval(mi.BSDFContext(), si, wo), dtype=np.float64).ravel()


@pytest.mark.parametrize('variant', VARIANTS)
def test_twist_map_turns_the_tracks_point_by_point(variant):
    """A checkerboard of 10 and 70 degrees: in each cell the material is the
    one with that twist as a number; a uniform map is the number itself."""
    mi = stam_mitsuba.setup(variant)
    checker_map = {'type': 'checkerboard', 'color0': 10.0, 'color1': 70.0,
                   'to_uv': mi.ScalarTransform4f().scale([2, 2, 1])}
    checker = mi.load_dict({**BRUSHED, 'twist': checker_map})
    uniform = mi.load_dict({**BRUSHED, 'twist': {'type': 'uniform', 'value': 30.0}})
    tex = mi.load_dict(checker_map)
    seen = set()
    for uv in ((0.1, 0.1), (0.35, 0.1), (0.1, 0.35)):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.uv = mi.Point2f(*uv)
        t = float(np.array(tex.eval_1(si)).ravel()[0])   # the map's value there
        seen.add(t)
        number = mi.load_dict({**BRUSHED, 'twist': t})
        assert np.allclose(eval_at(mi, checker, uv), eval_at(mi, number, uv), rtol=1e-5), uv
    assert seen == {10.0, 70.0}
    ten, seventy = (eval_at(mi, mi.load_dict({**BRUSHED, 'twist': t}), (0.1, 0.1))
                    for t in (10.0, 70.0))
    assert not np.allclose(ten, seventy, rtol=1e-2)   # the twist matters here
    thirty = eval_at(mi, mi.load_dict({**BRUSHED, 'twist': 30.0}), (0.4, 0.8))
    assert np.allclose(eval_at(mi, uniform, (0.4, 0.8)), thirty, rtol=1e-5)
    assert mi.has_flag(checker.flags(), mi.BSDFFlags.Anisotropic)


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_a_texture_elsewhere_is_refused_by_name(variant):
    mi = stam_mitsuba.setup(variant)
    with pytest.raises(Exception) as e:
        mi.load_dict({**BRUSHED, 'corr_x_um': {'type': 'uniform', 'value': 0.1}})
    assert "'corr_x_um' cannot take a texture" in str(e.value), str(e.value)


SMOOTH_TO_ROUGH = [[0.02, 0.3], [0.1, 0.5]]   # sigma_um per texel (um)


def sigma_map(mi, values, **extra):
    data = np.array(values, dtype=np.float32)[..., None]
    return {'type': 'bitmap', 'bitmap': mi.Bitmap(data), 'raw': True,
            'filter_type': 'nearest', **extra}


TEXELS = (((0, 0), (0.25, 0.25)), ((0, 1), (0.75, 0.25)),
          ((1, 0), (0.25, 0.75)), ((1, 1), (0.75, 0.75)))


def texels_match_numbers(mi, mapped, base, key, grid, rtol, atol, wo=(-0.1, -0.5)):
    """At each texel of a 2 x 2 map on parameter `key`, the mapped material
    evaluates (at wo) as `base` with that texel's value as a number; the
    evaluations, texel by texel."""
    values = []
    for (row, col), uv in TEXELS:
        number = mi.load_dict({**base, key: grid[row][col]})
        got, want = (eval_at(mi, b, uv, wo=wo) for b in (mapped, number))
        assert want.max() > 0
        assert np.allclose(got, want, rtol=rtol, atol=atol * want.max()), (uv, got, want)
        values.append(got)
    return values


def samples_fit_pdf_at(mi, bsdf, uv, ires, wi=(0.6, 0.0, 0.8)):
    """Chi-square of the glossy samples against the pdf at texture point
    uv (test_plugin's adapter; `ires` integration points per cell). 400,000
    samples: with 200,000 the stock test pools a few hundred sparse cells of
    a grating's RGB rainbows and its p-value sat at 0.009-0.04 for the
    mapped sine grating and for the plain ones alike (0.12 and 0.4 um, two
    incidences), 0.42-0.80 with 400,000."""
    from test_plugin import density_adapter, glossy_ctx
    sample, pdf = density_adapter(bsdf, list(wi), glossy_ctx(),
                                  WAVELENGTHS if mi.is_spectral else None, uv=uv)
    chi2 = mi.chi2.ChiSquareTest(domain=mi.chi2.SphericalDomain(), sample_func=sample,
                                 pdf_func=pdf, sample_dim=3, sample_count=400000, res=101,
                                 ires=ires)
    assert chi2.run(), chi2.messages


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
@pytest.mark.parametrize('fresnel', [0.9, 'gold'])
def test_sigma_map_gives_each_point_its_sigma(variant, fresnel):
    """A 2 x 2 sigma map from 0.02 to 0.5 um: at each texel the material is
    the one with that sigma as a number (the programs are built for every
    sigma up to 0.5; the sampling follows the point's sigma)."""
    mi = stam_mitsuba.setup(variant)
    # Stam's formula: a sigma texture's default; the numbers' default
    # (energy conserving) has a table per sigma
    base = {'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0, 'fresnel': fresnel,
            'energy': 'stam'}
    mapped = mi.load_dict({**base, 'sigma_um': sigma_map(mi, SMOOTH_TO_ROUGH)})
    assert 'sigma_um_max = 0.5 (from the texture)' in str(mapped)
    values = texels_match_numbers(mi, mapped, base, 'sigma_um', SMOOTH_TO_ROUGH, 2e-4, 1e-7)
    assert not np.allclose(values[0], values[3], rtol=0.1)   # sigma matters here


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_sigma_map_samples_weigh_f_cos_over_pdf(variant):
    """Samples at random points of the map: weight = f cos / pdf at the
    sampled direction (glossy), each lane with its own sigma."""
    mi = stam_mitsuba.setup(variant)
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0,
                         'fresnel': 0.9, 'sigma_um': sigma_map(mi, SMOOTH_TO_ROUGH)})
    n = 4096
    rng = np.random.default_rng(3)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    cos_i = rng.uniform(0.1, 1.0, n)
    si.wi = mi.Vector3f(np.sqrt(1 - cos_i ** 2), 0 * cos_i, cos_i)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(rng.uniform(0, 1, n), rng.uniform(0, 1, n))
    if mi.is_spectral:
        si.wavelengths = WAVELENGTHS
    ctx = mi.BSDFContext(mi.TransportMode.Radiance, mi.BSDFFlags.GlossyReflection)
    bs, weight = bsdf.sample(ctx, si, mi.Float(rng.uniform(0, 1, n)),
                             mi.Point2f(rng.uniform(0, 1, n), rng.uniform(0, 1, n)))
    value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    w, v = np.array(weight), np.array(value)
    p, sp = np.array(pdf), np.array(bs.pdf)
    ok = sp > 0
    assert ok.sum() > 1000   # (the rest chose the coherent lobe, which ctx excludes)
    assert np.allclose(p[ok], sp[ok], rtol=1e-3)
    assert np.allclose(w[..., ok] * sp[ok], v[..., ok], rtol=2e-3, atol=1e-6)
    assert np.all(np.isfinite(w)) and np.all(w >= 0)


def test_sigma_map_is_refused_where_it_cannot_go():
    mi = stam_mitsuba.setup('scalar_rgb')
    with pytest.raises(Exception) as e:
        mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0,
                      'sigma_um': {'type': 'uniform', 'value': 0.1}})
    assert "'sigma_um' takes a texture only in the JIT variants" in str(e.value), str(e.value)
    mi = stam_mitsuba.setup('llvm_ad_rgb')
    with pytest.raises(Exception) as e:
        mi.load_dict({'type': 'diffraction', 'surface': 'fractal', 'hurst': 0.7, 'lag_um': 2.0,
                      'sigma_um': {'type': 'uniform', 'value': 0.1}})
    assert 'only on surface "gaussian"' in str(e.value), str(e.value)
    with pytest.raises(Exception) as e:
        mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0,
                      'sigma_um': sigma_map(mi, [[0.0, -0.2], [0.0, 0.0]])})
    assert "'sigma_um': the texture's largest value" in str(e.value), str(e.value)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_sigma_map_samples_follow_the_points_sigma(variant):
    """Chi-square of the sampled directions against the pdf at a texel whose
    sigma (0.08 um) is far from the map's mean (0.395 um, the built one):
    the sampling program reads the point's sigma, as the pdf does."""
    mi = stam_mitsuba.setup(variant)
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0,
                         'fresnel': 0.9, 'sigma_um': sigma_map(mi, [[0.08, 0.5], [0.5, 0.5]])})
    samples_fit_pdf_at(mi, bsdf, (0.25, 0.25), ires=8)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_sigma_map_bad_values_give_finite_results(variant):
    """Negative and zero values read as the smoothest sigma (1e-6 um);
    values above the given sigma_um_max as that maximum (NaN is refused:
    test_nan_texels_are_refused_naming_the_parameter)."""
    mi = stam_mitsuba.setup(variant)
    base = {'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0, 'fresnel': 0.9,
            'energy': 'stam'}
    bad = mi.load_dict({**base, 'sigma_um_max': 0.2,
                        'sigma_um': sigma_map(mi, [[-0.3, 0.0], [-1e-3, 0.9]])})
    for uv in ((0.25, 0.25), (0.75, 0.25), (0.25, 0.75)):
        got = eval_at(mi, bad, uv)
        assert np.all(np.isfinite(got)) and np.all(got >= 0), (uv, got)
    capped = mi.load_dict({**base, 'sigma_um': 0.2})
    assert np.allclose(eval_at(mi, bad, (0.75, 0.75)), eval_at(mi, capped, (0.75, 0.75)),
                       rtol=2e-4)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_height_map_gives_each_point_its_groove_depth(variant):
    """A compact disc whose bump height is a texture (a 2 x 2 map of 0.08 to
    0.2 um): at each texel the disc with that height as a number."""
    mi = stam_mitsuba.setup(variant)
    heights = [[0.08, 0.2], [0.15, 0.11]]
    # Stam's formula: the default energy table is built for one height
    # (the texture's mean), the numbers' each for its own
    base = {'type': 'diffraction', 'surface': 'cd', 'coherence_um': 10.0, 'fresnel': 0.9,
            'energy': 'stam'}
    mapped = mi.load_dict({**base, 'height_um': sigma_map(mi, heights)})
    # wo on the first order's peak near 520 nm (u = -0.2, v = 0)
    values = texels_match_numbers(mi, mapped, base, 'height_um', heights, 1e-3, 1e-6,
                                  wo=(-0.1, -0.2))
    assert not np.allclose(values[0], values[1], rtol=0.05)   # the depth matters here


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_sine_height_map_gives_each_point_its_height(variant):
    """A sine grating whose height is a texture (a 2 x 2 map of 0.05 to
    0.4 um): the programs are built for every height up to the map's
    largest (`height_um_max`), and at each texel the grating is the one
    with that height as a number; its samples fit its pdf there."""
    mi = stam_mitsuba.setup(variant)
    heights = [[0.05, 0.4], [0.2, 0.12]]
    base = {'type': 'diffraction', 'surface': 'periodic', 'period_um': 1.2, 'profile': 'sine',
            'coherence_um': 6.0, 'fresnel': 0.9, 'energy': 'stam'}
    mapped = mi.load_dict({**base, 'height_um': sigma_map(mi, heights)})
    assert 'height_um_max = 0.4 (from the texture)' in str(mapped), str(mapped)
    # wo on the first order's peak near 550 nm (u = -0.46, v = 0)
    values = texels_match_numbers(mi, mapped, base, 'height_um', heights, 2e-3, 1e-6,
                                  wo=(-0.76, -0.2))
    assert not np.allclose(values[0], values[1], rtol=0.05)   # the height matters here
    # Gratings' peaks need 32 integration points per cell (test_plugin)
    samples_fit_pdf_at(mi, mapped, (0.75, 0.25), ires=32)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_sine_height_map_bad_values_give_finite_results(variant):
    """A sine grating's height map: negative and zero values read as a flat
    surface (height 0, a mirror's order 0 only); values above the given
    height_um_max as that maximum (NaN is refused)."""
    mi = stam_mitsuba.setup(variant)
    base = {'type': 'diffraction', 'surface': 'periodic', 'period_um': 1.2, 'profile': 'sine',
            'coherence_um': 6.0, 'fresnel': 0.9, 'energy': 'stam'}
    bad = mi.load_dict({**base, 'height_um_max': 0.3,
                        'height_um': sigma_map(mi, [[-0.3, 0.0], [-1e-3, 0.9]])})
    wo = (-0.76, -0.2)   # on the first order's peak
    for uv in ((0.25, 0.25), (0.75, 0.25), (0.25, 0.75)):
        got = eval_at(mi, bad, uv, wo=wo)
        assert np.all(np.isfinite(got)) and np.all(got >= 0), (uv, got)
        assert got.max() < 1e-3 * eval_at(mi, bad, (0.75, 0.75), wo=wo).max(), (uv, got)
    capped = mi.load_dict({**base, 'height_um': 0.3})
    assert np.allclose(eval_at(mi, bad, (0.75, 0.75), wo=wo),
                       eval_at(mi, capped, (0.75, 0.75), wo=wo), rtol=2e-3)


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_nan_texels_are_refused_naming_the_parameter(variant):
    """A map holding NaN (everywhere, or at one texel) is refused with a
    message naming its parameter, not read as some number (an all-NaN
    sigma map once reported 'largest value is 0.000000'): sigma and height
    maps (JIT variants), twist maps (every variant; also infinite angles)."""
    mi = stam_mitsuba.setup(variant)
    nan, inf = float('nan'), float('inf')

    def refused(params, key, what):
        with pytest.raises(Exception) as e:
            mi.load_dict(params)
        msg = str(e.value)
        assert "parameter '%s'" % key in msg and what in msg, msg
        assert 'largest value' not in msg, msg

    maps = ([[nan, nan], [nan, nan]], [[0.1, nan], [0.2, 0.3]])
    if not variant.startswith('scalar'):
        gaussian = {'type': 'diffraction', 'surface': 'gaussian', 'corr_um': 2.0}
        disc = {'type': 'diffraction', 'surface': 'cd'}
        for values in maps:
            refused({**gaussian, 'sigma_um': sigma_map(mi, values)}, 'sigma_um', 'NaN')
            refused({**disc, 'height_um': sigma_map(mi, values)}, 'height_um', 'NaN')
    for values in maps + ([[10.0, inf], [0.0, 0.0]],):
        refused({**BRUSHED, 'twist': sigma_map(mi, values)}, 'twist',
                'NaN' if np.isnan(values).any() else 'infinite')
    # Numbers everywhere are taken
    mi.load_dict({**BRUSHED, 'twist': sigma_map(mi, [[10.0, -400.0], [0.0, 1e6]])})


def test_height_map_is_refused_where_it_cannot_go():
    mi = stam_mitsuba.setup('llvm_ad_rgb')
    with pytest.raises(Exception) as e:
        mi.load_dict({'type': 'diffraction', 'surface': 'periodic', 'period_um': 1.2,
                      'coherence_um': 6.0, 'profile': '0, 0.1, 0.05',
                      'height_um': {'type': 'uniform', 'value': 0.1}})
    assert "'height_um' takes a texture only with the rect and sine profiles" in str(e.value), \
        str(e.value)


MAP_GRADIENTS = [
    ('twist.value', {**BRUSHED, 'twist': {'type': 'uniform', 'value': 25.0}}, 2.0),
    ('sigma_um.value', {'surface': 'gaussian', 'corr_um': 2.0, 'fresnel': 0.9,
                        'sigma_um_max': 0.2, 'sigma_um': {'type': 'uniform', 'value': 0.1}},
     0.002),
    ('height_um.value', {'surface': 'periodic', 'period_um': 1.2, 'profile': 'rect',
                         'width_um': 0.4, 'coherence_um': 6.0, 'fresnel': 0.9,
                         'height_um': {'type': 'uniform', 'value': 0.15}}, 0.004),
]
SINE_HEIGHT_MAP = ('height_um.value', {'surface': 'periodic', 'period_um': 1.2,
                                       'profile': 'sine', 'coherence_um': 6.0, 'fresnel': 0.9,
                                       'height_um_max': 0.3,
                                       'height_um': {'type': 'uniform', 'value': 0.2}}, 0.004)


# The sine map's gradient in llvm_ad_spectral only: in llvm_ad_rgb its kernel
# takes 17 s to compile, and tests/test_gradients.py checks the sine height's
# RGB gradient (the same parameter, given as a number).
@pytest.mark.parametrize('variant,key,bsdf,step',
                         [(v, *case) for v in ('llvm_ad_rgb', 'llvm_ad_spectral')
                          for case in MAP_GRADIENTS] + [('llvm_ad_spectral', *SINE_HEIGHT_MAP)])
def test_map_values_are_differentiable(variant, key, bsdf, step):
    """d(mean of a render)/d(a map's value) against a central difference,
    with the same samples (tests/test_gradients.py's method): the twist,
    sigma and height maps (mi.traverse: <parameter>.<the texture's>)."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import test_gradients as tg
    tg.assert_gradient(variant, key, {k: v for k, v in bsdf.items() if k != 'type'}, step)
