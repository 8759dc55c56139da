"""The `heightmap` surface in the Mitsuba plugin (docs/heightmap.md): the
map file found by Mitsuba's file resolver, eval equal to the core's f * cos
in scalar and JIT variants, sampling weights, the demo scene in several
variants, mi.traverse, and refusals by name.

The maps are those of `make heightmaps` (scripts/make_heightmaps.py,
scenes/heightmaps/); the tests make them when they are missing.

Run: make plugin heightmaps && .venv/bin/python -m pytest tests/test_heightmap.py
"""

import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
sys.path.insert(0, os.path.join(ROOT, 'python'))
# before drjit: the package sets DRJIT_LIBLLVM_PATH and DRJIT_CACHE_DIR
import stam_mitsuba  # noqa: E402
from stam_diffraction import core as stam_core  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

SCENES = os.path.join(ROOT, 'scenes')
MAPS = os.path.join(SCENES, 'heightmaps')
NAMES = ('gaussian', 'fractal', 'grating', 'scales')


@pytest.fixture(scope='module', autouse=True)
def maps():
    if not all(os.path.exists(os.path.join(MAPS, n + '.npy')) for n in NAMES):
        subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'make_heightmaps.py'),
                        '--out', MAPS], check=True)


def use(variant):
    stam_mitsuba.setup(variant)
    # The scenes' folder, as when Mitsuba loads scenes/heightmap.xml.
    mi.file_resolver().prepend(SCENES)


def material(name, **extra):
    d = {'type': 'diffraction', 'surface': 'heightmap', 'file': 'heightmaps/%s.npy' % name,
         'pixel_um': 0.08}
    d.update(extra)
    return d


def core_params(name, **extra):
    d = {'surface': 'heightmap', 'file': os.path.join(MAPS, name + '.npy'), 'pixel_um': 0.08}
    d.update(extra)
    return d


def to_np(x):
    return np.array(x, dtype=np.float64)


def make_si(wi, n=1, wavelengths=(450.0, 520.0, 590.0, 660.0)):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.5, 0.5)
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    if mi.is_spectral:
        si.wavelengths = list(wavelengths)
    return si


def lobe_dirs(wi, n, seed):
    """Directions about wi's mirror (where the maps' lobes are)."""
    rng = np.random.default_rng(seed)
    m = np.array([-wi[0], -wi[1], wi[2]])
    d = m + rng.normal(scale=0.15, size=(n, 3)) * [1, 1, 0]
    d /= np.linalg.norm(d, axis=1)[:, None]
    return d[d[:, 2] > 0.05]


WI = [0.3, 0.2, float(np.sqrt(1 - 0.13))]


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
@pytest.mark.parametrize('name', ['gaussian', 'grating'])
def test_eval_equals_core_times_cos_rgb(variant, name):
    use(variant)
    b = mi.load_dict(material(name))
    wo = lobe_dirs(WI, 200, seed=3)
    with stam_core.Brdf(core_params(name)) as core:
        ref = core.eval_rgb(np.tile(WI, (len(wo), 1)), wo) * wo[:, 2:3]
    ctx = mi.BSDFContext()
    if variant.startswith('scalar'):
        got = np.array([to_np(b.eval(ctx, make_si(WI), mi.Vector3f(d))) for d in wo])
    else:
        si = make_si(WI, n=len(wo))
        got = to_np(b.eval(ctx, si, mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2]))).T
    scale = ref.max()
    assert scale > 0
    err = np.abs(got - ref).max() / scale
    print('%s %s: eval against the core: %.2e of the largest value' % (variant, name, err))
    assert err < 1e-3


@pytest.mark.parametrize('variant', ['scalar_spectral', 'llvm_ad_spectral'])
def test_eval_equals_core_times_cos_spectral(variant):
    use(variant)
    b = mi.load_dict(material('scales'))
    wo = lobe_dirs(WI, 200, seed=4)
    lams = (450.0, 520.0, 590.0, 660.0)
    ctx = mi.BSDFContext()
    if variant.startswith('scalar'):
        got = np.array([to_np(b.eval(ctx, make_si(WI, wavelengths=lams), mi.Vector3f(d)))
                        for d in wo])
    else:
        si = make_si(WI, n=len(wo), wavelengths=lams)
        got = to_np(b.eval(ctx, si, mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2]))).T
    with stam_core.Brdf(core_params('scales')) as core:
        for j, lam in enumerate(lams):
            ref = core.eval_spectral(np.tile(WI, (len(wo), 1)), wo, lam) * wo[:, 2]
            err = np.abs(got[:, j] - ref).max() / ref.max()
            assert err < 1e-3, (lam, err)


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_sample_weight_is_eval_over_pdf(variant):
    use(variant)
    b = mi.load_dict(material('gaussian'))
    ctx = mi.BSDFContext()
    n = 2000
    rng = np.random.default_rng(5)
    s = rng.random((n, 3))
    if variant.startswith('scalar'):
        rows = []
        for i in range(0, n, 10):
            si = make_si(WI)
            bs, w = b.sample(ctx, si, float(s[i, 0]), mi.Point2f(s[i, 1], s[i, 2]))
            if bs.pdf > 0 and not mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta):
                v, p = b.eval_pdf(ctx, si, bs.wo)
                rows.append((to_np(w), to_np(v), float(p), float(bs.pdf)))
        assert len(rows) > 50
        for w, v, p, bp in rows:
            assert np.isclose(bp, p, rtol=1e-3)
            assert np.allclose(w * bp, v, rtol=1e-3, atol=1e-6)
    else:
        si = make_si(WI, n=n)
        bs, w = b.sample(ctx, si, mi.Float(s[:, 0]), mi.Point2f(s[:, 1], s[:, 2]))
        v, p = b.eval_pdf(ctx, si, bs.wo)
        delta = to_np(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)) > 0
        w, v, p, bp = to_np(w), to_np(v), to_np(p), to_np(bs.pdf)
        ok = (bp > 0) & ~delta
        assert ok.sum() > n // 10 and delta.sum() > 0
        assert np.allclose(bp[ok], p[ok], rtol=1e-3)
        assert np.allclose((w * bp)[:, ok], v[:, ok], rtol=1e-3, atol=1e-6)


def test_traverse_and_refusals():
    use('scalar_rgb')
    b = mi.load_dict(material('grating'))
    params = mi.traverse(b)
    keys = {k.split('.')[-1] for k in params.keys()}
    assert {'file', 'pixel_um', 'height_scale_um', 'rgb_nodes'} <= keys, keys
    with pytest.raises(Exception, match="cannot read height map"):
        mi.load_dict(material('missing'))
    with pytest.raises(Exception, match="pixel_um"):
        mi.load_dict({'type': 'diffraction', 'surface': 'heightmap',
                      'file': 'heightmaps/gaussian.npy'})


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_demo_scene_renders(variant):
    """scenes/heightmap.xml renders finite, non-negative and lit in each
    variant, every sphere brighter than the floor's share."""
    use(variant)
    scene = mi.load_file(os.path.join(SCENES, 'heightmap.xml'), res=48, spp=16)
    img = to_np(mi.render(scene))
    assert np.all(np.isfinite(img)) and img.min() >= 0
    assert img.mean() > 1e-3
    print('%s: mean %.4f' % (variant, img.mean()))


def test_an_exr_map_renders_as_its_npy_twin(tmp_path):
    """A map saved by Mitsuba as a one-channel OpenEXR image gives the same
    BSDF as the .npy it came from."""
    use('scalar_rgb')
    h = np.load(os.path.join(MAPS, 'scales.npy'))[:256, :256].astype(np.float32)
    np.save(tmp_path / 'map.npy', h)
    mi.Bitmap(h[:, :, None], mi.Bitmap.PixelFormat.Y).write(str(tmp_path / 'map.exr'))
    wo = lobe_dirs(WI, 40, seed=6)
    ctx = mi.BSDFContext()
    vals = []
    for ext in ('npy', 'exr'):
        b = mi.load_dict({'type': 'diffraction', 'surface': 'heightmap', 'pixel_um': 0.08,
                          'file': str(tmp_path / ('map.' + ext))})
        vals.append(np.array([to_np(b.eval(ctx, make_si(WI), mi.Vector3f(d))) for d in wo]))
    assert vals[0].max() > 0
    assert np.allclose(vals[0], vals[1], rtol=1e-6, atol=1e-9)
