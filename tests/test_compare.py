"""Mitsuba (diffraction plugin) vs the Rust-only renderer (tools/render), small images.

A fast subset of scripts/compare.py (`make compare` runs the full one): the same
flat sample, pinhole camera and point light rendered by Mitsuba's `direct`
integrator and by `stam-render`, at the same sub-pixel positions. Needs
build/plugins/diffraction.so, target/release/stam-render and libstam.so
(`make test-python` builds them).
"""

import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import compare  # noqa: E402


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
