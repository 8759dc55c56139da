"""Mitsuba (diffraction plugin) vs the Rust-only renderer (tools/render), small images.

A fast subset of scripts/compare.py (`make compare` runs the full one): the same
flat sample, pinhole camera and point light rendered by Mitsuba's `direct`
integrator and by `stam-render`, at the same sub-pixel positions; and the
plugin's JIT eval against its native eval at that scene's shading points.
Needs build/plugins/diffraction.so, target/release/stam-render and libstam.so
(`make test-python` builds them).
"""

import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import compare  # noqa: E402
import stam_accuracy  # noqa: E402
import stam_mitsuba  # noqa: E402


@pytest.fixture(scope='module')
def out_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp('compare'))


# jit: llvm_ad_rgb / llvm_ad_spectral with Dr.Jit's default flags (the plugin
# executing the core's programs) instead of scalar_rgb / scalar_spectral.
CASES = [(m, jit) for jit in (False, True)
         for m in ('gaussian', 'gaussian_aniso', 'fractal', 'periodic', 'cd')]


@pytest.mark.parametrize('model,jit', CASES)
def test_rgb_matches_rust_only(model, jit, out_dir):
    r = compare.check_image(model, 'rgb', 32, 2, out_dir, pictures=False, jit=jit)
    assert r['pixels'] > 200
    assert r['mean_ref'] > 0
    assert r['rel_rmse'] <= compare.RMSE_LIMIT, r


@pytest.mark.parametrize('model,jit', [('gaussian_aniso', False), ('periodic', False),
                                       ('gaussian_aniso', True), ('fractal', True),
                                       ('periodic', True)])
def test_spectral_bands_match_rust_only(model, jit, out_dir):
    r = compare.check_image(model, 'bands', 32, 4, out_dir, pictures=False, jit=jit)
    assert r['mean_ref'] > 0
    assert r['bias'] <= compare.RMSE_LIMIT, r


def test_cd_bands_match_rust_only_jit(out_dir):
    """The compact disc's bands in llvm_ad_spectral (issue 47): the noise is
    heavy-tailed (narrow peaks hit by few wavelengths: ~7 % per render at 32x32,
    64 spp), and the systematic estimate of two seeds, the former gate, reads 0
    to 11 % on pairs of seeds (224 of 512 pairs above 1 %) where the JIT eval
    equals the native one to 3e-7 (test_jit_eval_equals_native). 128 seeds:
    within 0.31 % on each of 8 disjoint seed sets, standard error 0.4-0.7 %. At
    16 spp the seed average of the disc's bands differs from the reference by
    ~1.6 % in scalar_spectral and llvm_ad_spectral alike (the same residual in
    both, which seeds do not remove): 64 spp."""
    r = compare.check_image('cd', 'bands', 32, 8, out_dir, pictures=False, jit=True,
                            seeds=128, se_target=None)
    assert r['seeds'] == 128 and r['mean_ref'] > 0
    assert r['bias'] <= compare.RMSE_LIMIT, r


def test_twist_is_seen(out_dir):
    """Negative control: the comparison detects a frame error (the Rust-only
    image without the twist differs from Mitsuba's with it)."""
    cfg = compare.config('gaussian_aniso', 32, 32, 2)
    ref, cov, _ = compare.render_rust(dict(cfg, twist_deg=0.0))
    test, _ = compare.render_mitsuba('scalar_rgb', cfg)
    r = compare.image_metrics(test, ref, compare.interior_mask(cov))
    assert r['rel_rmse'] > 10 * compare.RMSE_LIMIT


def test_concentric_tracks_are_seen(out_dir):
    """Negative control: linear vs concentric tracks on the CD differ."""
    cfg = compare.config('cd', 32, 32, 2)
    ref, cov, _ = compare.render_rust(dict(cfg, tracks='linear'))
    test, _ = compare.render_mitsuba('scalar_rgb', cfg)
    r = compare.image_metrics(test, ref, compare.interior_mask(cov))
    assert r['rel_rmse'] > 10 * compare.RMSE_LIMIT


@pytest.mark.parametrize('model', ['gaussian_aniso', 'cd'])
def test_slices(model, out_dir):
    r = compare.check_slices(model, out_dir, pictures=False)
    assert r['max_rel_diff'] <= compare.SLICE_LIMIT, r


def test_cd_spectral_vs_rgb(out_dir):
    r = compare.check_cd_spectral_vs_rgb(48, 8, out_dir, pictures=False)
    assert r['lit_pixels'] > 10
    assert max(abs(x) for x in r['channel_sum_err']) <= compare.SPECTRAL_RGB_LIMIT, r
    assert abs(r['luminance_sum_err']) <= compare.SPECTRAL_RGB_LIMIT, r


# The plugin's JIT eval (llvm_ad_*: the core's programs) against its native
# eval (scalar_*) at the shading points of the compare scene's pixel centres
# (camera rays through them, the point light's direction), deterministic: what
# the image checks see, without their Monte Carlo noise. The scalar side gets
# the llvm side's float32 shading points (wi, wo, uv, dp_du, dp_dv, sh_frame),
# so the two differ only by their eval. Every model of compare.py, and the
# disc's default material (energy included) with concentric tracks.
EVAL_SIZE = 48
EVAL_OFFSETS_NM = (-0.75, -0.3, 0.0, 0.4, 0.8)   # inside each of compare.BANDS_NM
# Relative RMS over the valid pixels, channels and wavelength sets. Spectral:
# the 1e-4 (the program within 1e-4 of the core); measured 3e-7 to
# 4e-6 here (AVX-512), so other machines' vector code (Dr.Jit's exp, sin and
# fused multiply-adds) keeps a 25x margin, while a 2 % error (issue 47's
# suspicion) or a 1e-3 table mismatch fails. (Tracing the rays in each variant
# instead adds the two intersections' rounding: 9e-5 on the disc, whose
# spectral spikes move with wo.) RGB: the documented error of each model's
# RGB rule (stam_accuracy.RGB_DOCUMENTED; the disc as a grating); measured
# 7e-7 to 2e-6 (smooth kernels), 4.5e-5 (disc), 1.3e-4 (sine grating).
SPECTRAL_EVAL_TOL = stam_accuracy.SPECTRAL_TOL
EVAL_CASES = [(m, None) for m in compare.MODELS] + [('cd', {'surface': 'cd'})]


def _eval_cfg(model, material):
    cfg = compare.config(model, EVAL_SIZE, EVAL_SIZE, 1)
    if material is not None:
        cfg['material'] = material
    return cfg


def _jit_eval(cfg, lam_sets):
    """llvm: the shading points of the pixel centres, and the plugin's eval there
    (sets, pixels, channels); with the points' fields as numpy arrays."""
    mi = stam_mitsuba.setup('llvm_ad_rgb' if lam_sets is None else 'llvm_ad_spectral')
    import drjit as dr
    size = cfg['width']
    scene = mi.load_dict(compare.scene_dict(mi, cfg))
    j, i = np.meshgrid(np.arange(size), np.arange(size), indexing='ij')
    pos = mi.Point2f(((i.ravel() + 0.5) / size).astype(np.float32),
                     ((j.ravel() + 0.5) / size).astype(np.float32))
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    wo = si.to_local(dr.normalize(mi.Point3f(*cfg['light_pos']) - si.p))
    valid = np.array(si.is_valid())
    bsdf, ctx, n = si.bsdf(), mi.BSDFContext(), dr.width(si)
    vals = []
    for lams in lam_sets or [None]:
        if lams is not None:
            si.wavelengths = mi.UnpolarizedSpectrum(*[dr.full(mi.Float, lam, n)
                                                      for lam in lams])
        vals.append(np.array(bsdf.eval(ctx, si, wo, valid)).T)
    fields = {k: np.array(getattr(si, k)).T for k in ('wi', 'uv', 'dp_du', 'dp_dv')}
    fields['frame'] = [np.array(getattr(si.sh_frame, k)).T for k in 'stn']
    fields['wo'] = np.array(wo).T
    return valid, np.stack(vals), fields


def _native_eval(cfg, lam_sets, valid, fields):
    """scalar: the plugin's eval at the same shading points (the shape from the
    scalar trace of the same ray, every field the plugin reads from llvm's)."""
    mi = stam_mitsuba.setup('scalar_rgb' if lam_sets is None else 'scalar_spectral')
    size = cfg['width']
    scene = mi.load_dict(compare.scene_dict(mi, cfg))
    sensor, ctx = scene.sensors()[0], mi.BSDFContext()
    sets = lam_sets or [None]
    out = np.zeros((len(sets), valid.size, 3 if lam_sets is None else len(lam_sets[0])))
    for k in np.flatnonzero(valid):
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((k % size + 0.5) / size,
                                                        (k // size + 0.5) / size),
                                   mi.Point2f(0.5, 0.5))
        si = scene.ray_intersect(ray)
        assert si.is_valid()
        si.wi = mi.Vector3f(fields['wi'][k])
        si.uv = mi.Point2f(fields['uv'][k])
        si.dp_du = mi.Vector3f(fields['dp_du'][k])
        si.dp_dv = mi.Vector3f(fields['dp_dv'][k])
        si.sh_frame = mi.Frame3f(*[mi.Vector3f(a[k]) for a in fields['frame']])
        wo = mi.Vector3f(fields['wo'][k])
        bsdf = si.bsdf()
        for m, lams in enumerate(sets):
            if lams is not None:
                si.wavelengths = list(lams)
            v = bsdf.eval(ctx, si, wo)
            out[m, k] = [v[c] for c in range(out.shape[2])]
    return out


@pytest.mark.parametrize('spectral', [False, True], ids=['rgb', 'spectral'])
@pytest.mark.parametrize('model,material', EVAL_CASES,
                         ids=[m + ('_default' if mat else '') for m, mat in EVAL_CASES])
def test_jit_eval_equals_native(model, material, spectral):
    cfg = _eval_cfg(model, material)
    lam_sets = ([[b + o for b in compare.BANDS_NM] for o in EVAL_OFFSETS_NM]
                if spectral else None)
    valid, jit, fields = _jit_eval(cfg, lam_sets)
    native = _native_eval(cfg, lam_sets, valid, fields)
    assert valid.sum() > 500
    d, ref = (jit - native)[:, valid], native[:, valid]
    rms_ref = np.sqrt(np.mean(ref ** 2))
    assert rms_ref > 0 and np.all(np.isfinite(jit))
    err = np.sqrt(np.mean(d ** 2)) / rms_ref
    surface = cfg['material']['surface']
    tol = (SPECTRAL_EVAL_TOL if spectral
           else stam_accuracy.RGB_DOCUMENTED['periodic' if surface == 'cd' else surface])
    assert err <= tol, (err, tol, np.abs(d).max() / np.abs(ref).max())
