"""The JIT path of the `diffraction` plugin (issue 13), in renders: with
Dr.Jit's DEFAULT flags, a symbolic render equals the evaluated-mode one; a
dr.freeze-d render is recorded once and replayed, and follows parameter
updates; a symbolic render of a scene without the plugin works while
diffraction BSDFs exist; a mesh without uv is still refused; every test
material runs in a symbolic call; Mitsuba's chi-square test of the JIT
sampling at cos_i 1, 0.5, 0.1; the `mitsuba` command renders every scene of
scenes/. (tests/test_jit.py: the programs' values against the core; a file
apart, so that pytest's two workers share the JIT tests' kernel compiles.)
With STAM_JIT_REPORT=<file>, the p-values are appended to <file> as JSON
lines.

Run: make core plugin && .venv/bin/python -m pytest tests/test_jit_render.py
"""

import gc
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_jit import (  # noqa: E402  (the shared helpers; importing sets up the package)
    CHI2_SURFACES, JIT_VARIANTS, ROOT, SURFACES, WAVELENGTHS, make_si, programs, report,
    symbolic, to_np, use)
import stam_materials  # noqa: E402
import stam_mitsuba  # noqa: E402
from test_plugin import density_adapter, glossy_ctx  # noqa: E402
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

# ---------------------------------------------------------------------------
# Renders with the default flags
# ---------------------------------------------------------------------------

def scene_dict(shapes, integrator='path', res=32, spp=4):
    d = {
        'type': 'scene',
        'integrator': ({'type': integrator, 'max_depth': 4} if integrator == 'path'
                       else {'type': integrator}),
        'sensor': {'type': 'perspective', 'fov': 40,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -4, 4], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': res, 'height': res,
                            'rfilter': {'type': 'box'}},
                   'sampler': {'type': 'independent', 'sample_count': spp}},
        'light': {'type': 'point', 'position': [1.0, -2.0, 4.0],
                  'intensity': {'type': 'spectrum', 'value': 30.0}},
        'env': {'type': 'constant', 'radiance': {'type': 'spectrum', 'value': 0.3}},
    }
    d.update(shapes)
    return d


def load_model_scene(variant):
    """The scene of `model_shapes`, loaded in order (parallel=False): a
    symbolic call traces the variant's BSDFs in the order of their registry
    ids, which a parallel load hands out as its threads finish, so that the
    render's kernel (101,494 operations in llvm_ad_rgb, a minute of LLVM)
    would differ from one load to the next and miss Dr.Jit's cache; loaded
    in order, every test and process here renders the same kernel."""
    return mi.load_dict(scene_dict(model_shapes(variant)), parallel=False)


def model_shapes(variant):
    """One shape per surface model: a concentric compact
    disc on a disk (the frame from the shape's type), a Gaussian sphere, a
    brushed rectangle, a fractal sphere, a grating rectangle."""
    shapes = {}
    T = mi.ScalarTransform4f

    def add(name, surface, shape, **extra):
        params = SURFACES[surface]
        shape['bsdf'] = {'type': 'diffraction', **stam_materials.plugin_params(params), **extra}
        shapes[name] = shape
    add('cd', 'cd', {'type': 'disk', 'to_world': T().translate([-1.2, 0.6, 0]).scale(0.9)},
        tracks='concentric')
    add('gaussian', 'gaussian', {'type': 'sphere', 'center': [1.1, 0.8, 0.5], 'radius': 0.5})
    add('brushed', 'gaussian_aniso', {'type': 'rectangle',
                                      'to_world': T().translate([1.2, -1.0, 0]).scale(0.7)},
        twist=20.0)
    add('fractal', 'fractal', {'type': 'sphere', 'center': [-1.0, -1.1, 0.4], 'radius': 0.4})
    add('grating', 'periodic_sine', {'type': 'rectangle',
                                     'to_world': T().translate([0.0, 0.0, -0.01]).scale(0.6)})
    shapes['floor'] = {'type': 'rectangle', 'to_world': T().translate([0, 0, -0.02]).scale(3.0),
                       'bsdf': {'type': 'diffuse'}}
    return shapes


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_symbolic_render_equals_the_evaluated_one(variant):
    use(variant)
    scene = load_model_scene(variant)
    img = to_np(mi.render(scene, seed=3))
    # Spectral: a grating's nearly monochromatic light lies outside the sRGB
    # gamut (a negative channel), but its luminance is not negative
    y = img @ np.array([0.2126, 0.7152, 0.0722])
    assert np.all(np.isfinite(img)) and img.mean() > 0
    assert np.all(y >= -1e-6 * y.max()) and (mi.is_spectral or np.all(img >= 0))
    # the same kernels' arithmetic in wavefront (evaluated) mode
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False), \
            dr.scoped_set_flag(dr.JitFlag.SymbolicCalls, False):
        ref = to_np(mi.render(scene, seed=3))
    assert np.allclose(img, ref, rtol=1e-3, atol=1e-5 * ref.max())


def skip_unless_mitsuba_freezes_renders():
    """Mitsuba 3.9.1 cannot record a frozen spectral render, with or without
    this plugin (a 95-value spectral table of its own, the CIE 1931 curves,
    is not traversed): skip where a scene without the plugin fails."""
    scene = mi.load_dict(scene_dict({'ball': {'type': 'sphere', 'bsdf': {
        'type': 'roughconductor'}}}, res=8, spp=1))
    why = stam_mitsuba.freeze_failure(scene)
    if why is not None:
        pytest.skip('Mitsuba %s cannot freeze a render in %s, without the plugin too: %s'
                    % (mi.__version__, mi.variant(), why[:300]))


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_frozen_render_replays(variant):
    use(variant)
    skip_unless_mitsuba_freezes_renders()
    scene = load_model_scene(variant)
    plain = to_np(mi.render(scene, seed=1))

    @dr.freeze
    def frozen(scene_, seed):
        return mi.render(scene_, seed=seed)
    first = to_np(frozen(scene, dr.opaque(mi.UInt32, 1)))
    second = to_np(frozen(scene, dr.opaque(mi.UInt32, 2)))
    third = to_np(frozen(scene, dr.opaque(mi.UInt32, 1)))
    assert frozen.n_recordings == 1            # the later calls replayed
    assert np.allclose(first, plain, rtol=1e-5, atol=1e-7)
    assert np.array_equal(third, first)
    assert not np.array_equal(second, first)   # a replay with another seed
    assert np.all(np.isfinite(second))


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_frozen_render_follows_parameter_updates(variant):
    """mi.traverse updates rebuild the programs (a change of more than 2%)
    or move the values they read (at most 2%: the programs for the built
    values give way to the plain ones, jit_path.h); a frozen render sees
    the new material after each, in any order: the material's traversal
    shows its code's version, so that dr.freeze records again where the
    code changed (the second rebuild replayed the first's kernels before)."""
    use(variant)
    skip_unless_mitsuba_freezes_renders()
    params = SURFACES['gaussian']
    programs(params, variant)
    scene = mi.load_dict(scene_dict({'s': {'type': 'sphere', 'bsdf': {
        'type': 'diffraction', **stam_materials.plugin_params(params)}}}))

    @dr.freeze
    def frozen(scene_, seed):
        return mi.render(scene_, seed=seed)
    first = to_np(frozen(scene, dr.opaque(mi.UInt32, 1)))
    sp = mi.traverse(scene)
    key = [k for k in sp.keys() if k.endswith('fresnel') or k.endswith('sigma_um')]
    assert key, list(sp.keys())
    k = [k for k in key if k.endswith('sigma_um')][0]
    previous = first
    # rebuild, drift, rebuild again, drift, back to the built value
    for sigma in (0.3, 0.303, 0.45, 0.447, 0.45):
        sp[k] = sigma
        sp.update()
        img = to_np(frozen(scene, dr.opaque(mi.UInt32, 1)))
        plain = to_np(mi.render(scene, seed=1))
        assert np.allclose(img, plain, rtol=1e-5, atol=1e-7), sigma
        assert not np.array_equal(img, previous), sigma
        previous = img
    assert not np.allclose(first, previous, rtol=1e-2)


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_symbolic_render_of_another_scene_while_diffraction_bsdfs_exist(variant):
    """A symbolic virtual call traces every registered BSDF of the variant:
    with diffraction BSDFs alive (a random surface and a grating; each
    alive BSDF's programs go into the render's kernel, so that all eight
    test surfaces made a cold compile of this 32x32 render take 54 s), a
    scene without them renders."""
    use(variant)
    gc.collect()
    alive = [mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(SURFACES[s])})
             for s in ('gaussian_aniso', 'cd')]
    scene = mi.load_dict(scene_dict({'ball': {'type': 'sphere', 'bsdf': {
        'type': 'roughconductor', 'alpha': 0.2}}}))
    img = to_np(mi.render(scene, seed=2))
    assert np.all(np.isfinite(img)) and img.mean() > 0
    assert len(alive) > 0


def error_chain(e):
    msgs = []
    while e is not None:
        msgs.append(str(e))
        e = e.__cause__ or e.__context__
    return msgs


def test_mesh_without_uv_is_refused_in_a_symbolic_render(tmp_path):
    use('llvm_ad_rgb')
    programs(SURFACES['gaussian_aniso'], 'llvm_ad_rgb')
    obj = tmp_path / 'square.obj'
    obj.write_text('v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n')
    bsdf = {'type': 'diffraction', 'tracks': 'concentric',
            **stam_materials.plugin_params(SURFACES['gaussian_aniso'])}
    scene = mi.load_dict(scene_dict({'mesh': {'type': 'obj', 'filename': str(obj),
                                              'bsdf': bsdf}}, integrator='direct', res=8))
    with pytest.raises(Exception) as e:
        mi.render(scene, spp=1)
    assert any('texture coordinates' in m for m in error_chain(e.value))


@pytest.mark.parametrize('variant', JIT_VARIANTS)
def test_every_material_runs_in_symbolic_mode(variant):
    """Every material of tests/materials.json, and an energy-conserving one
    of each model, has the programs of the variant: it constructs and
    evaluates in a symbolic call (there is no other path in JIT variants)."""
    use(variant)
    entries = {e['name']: e['params'] for e in stam_materials.load()}
    for surface in ('gaussian', 'fractal', 'periodic_sine', 'cd'):
        entries['%s conserving' % surface] = dict(SURFACES[surface], energy='conserving')
    si = make_si([[0.3, 0.2, math.sqrt(1 - 0.13)], [0.0, 0.6, 0.8]] * 2)
    wo = mi.Vector3f([-0.3, 0.1, -0.3, 0.1], [-0.2, -0.5, -0.2, -0.5],
                     [math.sqrt(1 - 0.13), math.sqrt(0.74)] * 2)
    for name, params in entries.items():
        bsdf = mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)})
        v = to_np(symbolic(bsdf).eval(mi.BSDFContext(), si, wo))
        assert np.all(np.isfinite(v)) and np.all(v >= 0), name
        assert 'jit_programs = eval' in str(bsdf), name


# ---------------------------------------------------------------------------
# chi-square test of the JIT sampling
# ---------------------------------------------------------------------------

CHI2_COS = (1.0, 0.5, 0.1)
CHI2_IRES = {'gaussian': 8, 'fractal': 8, 'periodic': 32}


@pytest.mark.parametrize('variant', JIT_VARIANTS)
@pytest.mark.parametrize('cos_i', CHI2_COS)
@pytest.mark.parametrize('surface', list(CHI2_SURFACES))
def test_chi2_of_the_jit_sampling(variant, surface, cos_i):
    use(variant)
    params = CHI2_SURFACES[surface]
    programs(params, variant)
    bsdf = mi.load_dict({'type': 'diffraction', **stam_materials.plugin_params(params)})
    wi = [math.sqrt(1 - cos_i * cos_i), 0.0, cos_i]
    # test_plugin's adapter, through a symbolic call (as a render makes it)
    sample, pdf = density_adapter(symbolic(bsdf, evaluated=False), wi, glossy_ctx(),
                                  WAVELENGTHS if mi.is_spectral else None)
    # Gratings' peaks are narrower than the smooth models' lobes: their pdf
    # is integrated over each cell with more points (CHI2_IRES)
    chi2 = mi.chi2.ChiSquareTest(domain=mi.chi2.SphericalDomain(), sample_func=sample,
                                 pdf_func=pdf, sample_dim=3, sample_count=400000, res=101,
                                 ires=CHI2_IRES[stam_materials.model_of(params)])
    passed = chi2.run()
    report(test='chi2', variant=variant, surface=surface, cos_i=cos_i,
           p_value=None if chi2.p_value is None else float(chi2.p_value), passed=bool(passed))
    assert passed, chi2.messages


# ---------------------------------------------------------------------------
# The `mitsuba` command with its default variant (llvm_ad_rgb where LLVM is
# present) and Dr.Jit's default flags renders the project's scenes
# ---------------------------------------------------------------------------

SCENES_DIR = os.path.join(ROOT, 'scenes')


@pytest.fixture(scope='module')
def studio():
    """The hero scenes' studio environment and label (out/env/, written
    atomically by scripts/studio_env.py if missing), which no other test
    need have made first."""
    sys.path.insert(0, os.path.join(ROOT, 'scripts'))
    import studio_env
    return studio_env.write(os.path.join(ROOT, 'out', 'env'))


SCENES = sorted(f for f in os.listdir(SCENES_DIR) if f.endswith('.xml'))


def mitsuba_command(variant, scenes, out):
    """`mitsuba` (with -m variant unless None) at 24 px and 2 spp; `out`: the
    output file for one scene, or for several a directory where each scene
    (a copy, its resources found through -a scenes/) writes its image
    beside itself. The completed process."""
    exe = os.path.join(os.path.dirname(sys.executable), 'mitsuba')
    cmd = [exe, '-a', 'build', '-Dspp=2', '-Dres=24']
    if variant:
        cmd[1:1] = ['-m', variant]
    if len(scenes) == 1:
        cmd += ['-o', str(out), os.path.join(SCENES_DIR, scenes[0])]
    else:
        cmd[cmd.index('build')] = 'build;' + SCENES_DIR
        for scene in scenes:
            shutil.copy(os.path.join(SCENES_DIR, scene), os.path.join(out, scene))
        cmd += [os.path.join(out, scene) for scene in scenes]
    return subprocess.run(cmd, cwd=ROOT, env=dict(os.environ), capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope='module')
def every_scene_rendered(studio, tmp_path_factory):
    """{variant: (directory, completed process)} of one `mitsuba` command per
    variant given every scene of scenes/: a process each (26 of them) took
    about 2 s of CPU each to start before it rendered."""
    def run(variant):
        out = tmp_path_factory.mktemp('scenes_%s' % (variant or 'default'))
        return out, mitsuba_command(variant, SCENES, out)
    return {variant: run(variant) for variant in (None, 'llvm_ad_spectral')}


@pytest.mark.parametrize('variant', [None, 'llvm_ad_spectral'])
@pytest.mark.parametrize('scene', SCENES)
def test_mitsuba_command_renders_the_scene(scene, variant, tmp_path, every_scene_rendered):
    """`mitsuba` with its default variant (None: llvm_ad_rgb where LLVM is
    present) and with llvm_ad_spectral, Dr.Jit's default flags. The scenes
    render in one command per variant (every_scene_rendered); where that
    command failed or left this scene without its image, the scene is
    rendered alone, as before, and the test reads that command's outcome."""
    out_dir, r = every_scene_rendered[variant]
    out = os.path.join(out_dir, scene[:-4] + '.exr')
    if r.returncode != 0 or not os.path.exists(out):
        out = str(tmp_path / (scene[:-4] + '.exr'))
        r = mitsuba_command(variant, [scene], out)
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    use('llvm_ad_rgb')
    img = np.array(mi.Bitmap(out), dtype=np.float64)
    assert np.all(np.isfinite(img)) and img.mean() > 0, scene
