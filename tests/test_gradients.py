"""Gradients of rendered images with respect to the `diffraction` BSDF's
parameters (issue 14), in the AD variants with Dr.Jit's default flags.

The parameters the material's programs read (STAM_PARAM_* in stam.h: the
Gaussian model's sigma_um and correlation lengths, the fractal's sigma_um
and lag_um, a grating's period, coherence length, height and width, the
constant Fresnel reflectance and eta / k; and the plugin's twist) are
differentiable in mi.traverse; the others (hurst, a measured metal) are
not. For each, the gradient of a rendered image's mean (reverse mode) is
compared with the central finite difference of renders with the seed the
gradient pass draws its samples with (a point light, paths of one bounce:
no noise separates the two).

The integrator is Mitsuba's `prb`, except for the gratings' gradients:
there it is `direct` with emitter samples only. The image is the same (with
a point light a BSDF sample never reaches the light, so prb's BSDF-sampled
branch adds nothing to the image nor to its gradient), and it traces the
grating's RGB eval twice instead of prb's four times with their adjoints:
a gradient kernel of 65,000 operations instead of 192,000, which took 13
minutes to compile on a 2-core AMD EPYC (the rgb-sine test with an empty
kernel cache: 872 s -> 298 s, the same gradients). prb's own path replay
stays covered by the other gradients here and by test_inverse.py.

Run: make core plugin && .venv/bin/python -m pytest tests/test_gradients.py
"""

import gc
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))
import stam_mitsuba  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

VARIANTS = ['llvm_ad_rgb', 'llvm_ad_spectral']
# Relative agreement of the AD gradient with the finite difference (the 5%)
GRADIENT_TOL = 0.05


PRB = {'type': 'prb', 'max_depth': 2}
# Next-event estimation alone: the same image as PRB's with a point light
DIRECT = {'type': 'direct', 'emitter_samples': 1, 'bsdf_samples': 0}


def scene_dict(bsdf, res=24, integrator=PRB):
    T = mi.ScalarTransform4f
    return {
        'type': 'scene',
        'integrator': integrator,
        'sensor': {'type': 'perspective', 'fov': 40,
                   'to_world': T().look_at(origin=[0, -2.5, 2.5], target=[0, 0, 0],
                                           up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': res, 'height': res,
                            'rfilter': {'type': 'box'}},
                   'sampler': {'type': 'independent', 'sample_count': 16}},
        'plate': {'type': 'rectangle', 'bsdf': bsdf},
        'light': {'type': 'point', 'position': [0.6, 1.6, 2.2],
                  'intensity': {'type': 'spectrum', 'value': 20.0}},
    }


SEED = 7


def mean_of(scene, params=None, seed=SEED):
    return float(np.mean(np.array(mi.render(scene, params=params, seed=seed, spp=16))))


def check_gradients(bsdf, keys_steps):
    """Reverse-mode AD along every differentiable parameter of the material
    at once (one gradient pass, one kernel) against each key's central
    difference by +-its step: {key: (x0, fd, ad, values)}. Gratings with
    emitter samples only (the module's docstring says why).

    Every differentiable parameter carries a gradient in the pass, not
    only the keys checked: the gradient kernel then depends on the
    material's code alone, and the tests of one material family (the
    isotropic Gaussian's sigma_um and corr_um, the anisotropic one's
    correlation lengths and twist, eta and k, the fractal's sigma_um and
    lag_um) share it, which a cold run compiles once instead of once per
    key. A key's gradient is the same whichever others are
    differentiated."""
    integrator = DIRECT if bsdf.get('surface') == 'periodic' else PRB
    # The scenes of earlier tests freed: their BSDFs' registry ids would
    # differ, and with them the kernels
    gc.collect()
    scene = mi.load_dict(scene_dict(bsdf, integrator=integrator))
    params = mi.traverse(scene)
    full = {key: 'plate.bsdf.' + key for key, _ in keys_steps}
    for key, name in full.items():
        assert name in params, sorted(params.keys())
        assert params.flags(name) & mi.ParamFlags.NonDifferentiable.value == 0, name
    leaves = [k for k in params.keys() if k.startswith('plate.bsdf.')
              and not params.flags(k) & mi.ParamFlags.NonDifferentiable.value]
    x0 = {key: float(params[name][0]) for key, name in full.items()}
    at = {name: float(params[name][0]) for name in leaves}
    v = {}
    for name in leaves:
        v[name] = mi.Float(at[name])
        dr.enable_grad(v[name])
        params[name] = v[name]
    # reverse-mode AD of the render's mean (Mitsuba 3.9.1's prb cannot run
    # forward mode in spectral variants, with any BSDF). It comes first: a
    # parameter's first gradient rebuilds the material with its energy
    # table's derivatives, which the finite difference's renders below then
    # follow as well (within 2%; beyond, the table is rebuilt at the value)
    params.update()
    # The gradient pass draws its samples with seed_grad: the central
    # difference's renders use that seed (mean_of), so both see the same
    # samples and no Monte Carlo noise separates them
    img = mi.render(scene, params=params, seed=1, seed_grad=SEED, spp=16)
    dr.backward(dr.mean(img, axis=None))
    ad = {key: float(dr.grad(v[name])[0]) for key, name in full.items()}
    for name in leaves:
        params[name] = mi.Float(at[name])
    out = {}
    for key, step in keys_steps:
        # finite difference: same seed, the parameter moved both ways
        values = []
        for x in (x0[key] + step, x0[key] - step):
            params[full[key]] = mi.Float(x)
            params.update()
            values.append(mean_of(scene))
        params[full[key]] = mi.Float(x0[key])
        params.update()
        out[key] = (x0[key], (values[0] - values[1]) / (2 * step), ad[key], values)
    return out


@pytest.mark.parametrize('variant', VARIANTS)
@pytest.mark.parametrize('key,bsdf,step', [
    # The default: AD follows the energy table through its derivatives (the
    # programs read it as m + ln(p / p0) dm); a step of 1.9% keeps the
    # programs. Rebuilt tables jitter by ~1.4e-4 of this mean, which makes
    # the central difference of rebuilds a poor reference for sigma here
    # (docs/inverse.md, "The default's energy table")
    ('sigma_um', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5}, 0.0023),
    # Stam's formula: a step of 3.3% rebuilds the programs
    ('sigma_um', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5, 'energy': 'stam'},
     0.004),
    ('corr_um', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5}, 0.03),
    ('corr_x_um', {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 1.0,
                   'corr_y_um': 3.0}, 0.02),
    ('corr_y_um', {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 3.0,
                   'corr_y_um': 1.0}, 0.02),
    ('twist', {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 1.0,
               'corr_y_um': 3.0, 'twist': 25.0}, 2.0),
    ('fresnel', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5, 'fresnel': 0.7}, 0.01),
    ('eta', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5, 'eta': 1.5, 'k': 3.0},
     0.02),
    ('k', {'surface': 'gaussian', 'sigma_um': 0.12, 'corr_um': 1.5, 'eta': 1.5, 'k': 3.0}, 0.04),
    ('sigma_um', {'surface': 'fractal', 'sigma_um': 0.1, 'hurst': 0.7, 'lag_um': 1.0}, 0.003),
    ('lag_um', {'surface': 'fractal', 'sigma_um': 0.1, 'hurst': 0.7, 'lag_um': 1.0}, 0.03),
])
def test_gradient_equals_finite_difference(variant, key, bsdf, step):
    assert_gradient(variant, key, bsdf, step)


def assert_gradient(variant, key, bsdf, step):
    """check_gradients of one key in `variant` (key: the BSDF's parameter,
    or a texture's, 'twist.value'), printed and held to GRADIENT_TOL."""
    assert_gradients(variant, bsdf, [(key, step)])


def assert_gradients(variant, bsdf, keys_steps):
    """check_gradients in `variant`, printed and held to GRADIENT_TOL."""
    stam_mitsuba.setup(variant)
    results = check_gradients({'type': 'diffraction', **bsdf}, keys_steps)
    failures = []
    for key, (x0, fd, ad, values) in results.items():
        print('%s %s = %g: AD %.6g, central difference %.6g (means %s)'
              % (variant, key, x0, ad, fd, values))
        if not abs(fd) > 1e-4 * max(abs(v) for v in values):
            failures.append('%s: the parameter does not matter here' % key)
        elif not abs(ad - fd) <= GRADIENT_TOL * abs(fd):
            failures.append('%s: AD %g, central difference %g' % (key, ad, fd))
    assert not failures, failures


GRATING = {'surface': 'periodic', 'period_um': 1.2, 'profile': 'sine', 'height_um': 0.2,
           'coherence_um': 6.0, 'fresnel': 0.9}
RECT = {'surface': 'periodic', 'period_um': 1.2, 'profile': 'rect', 'height_um': 0.15,
        'width_um': 0.4, 'coherence_um': 6.0, 'fresnel': 0.9}


@pytest.mark.parametrize('variant', VARIANTS)
def test_parameters_the_programs_do_not_read_are_not_differentiable(variant):
    """mi.traverse marks Differentiable exactly what the variant's programs
    read, instead of giving silent zero gradients: a grating's period,
    height and coherence length in both; a fractal's hurst never."""
    stam_mitsuba.setup(variant)
    b = mi.load_dict({'type': 'diffraction', **GRATING})
    params = mi.traverse(b)
    for key in ('period_um', 'height_um', 'coherence_um'):
        differentiable = params.flags(key) & mi.ParamFlags.NonDifferentiable.value == 0
        assert differentiable, key
    g = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.1,
                      'corr_um': 1.0})
    assert mi.traverse(g).flags('sigma_um') & mi.ParamFlags.NonDifferentiable.value == 0
    f = mi.load_dict({'type': 'diffraction', 'surface': 'fractal', 'sigma_um': 0.1,
                      'hurst': 0.7, 'lag_um': 1.0})
    assert mi.traverse(f).flags('hurst') & mi.ParamFlags.NonDifferentiable.value


# Reverse against forward mode at the eval level: the sums over the lanes may
# differ by f32 rounding (reverse adds the lanes by atomic scatters), well
# below this share of the sum of the lanes' magnitudes
REVERSE_FORWARD_TOL = 1e-3

# The grating whose RGB programs reverse mode runs through in
# test_gradients_are_finite_and_reverse_equals_forward: a rect of period
# 1 um (plugin_periodic_rect's 2.5 um in forward mode only). Called directly
# (not through a symbolic call), Dr.Jit's reverse mode compiles about three
# kernels per region (symbolic if_stmt) of the program, each nearly the size
# of the whole forward pass: the 2.5 um rect's RGB eval has 12 regions in
# 8,634 instructions, and its reverse pass compiled 44 kernels (1.37 million
# operations, 255 s of a cold run on 2 cores); the 1 um rect's has 6 regions
# in 4,024 instructions, 24 kernels (0.34 million operations). Its regions
# read the same parameters (period, height, width, coherence length) in the
# same code, in which reverse mode came out 1,000-3,000 times too large
# without program.h's broadcast of width-1 live-ins.
RGB_REVERSE_RECT = {'surface': 'periodic', 'period_um': 1.0, 'profile': 'rect',
                    'height_um': 0.15, 'width_um': 0.4, 'coherence_um': 5.0, 'energy': 'stam'}


@pytest.mark.parametrize('variant', VARIANTS)
def test_gradients_are_finite_and_reverse_equals_forward(variant):
    """Every differentiable parameter of every test material at random,
    grazing and near-mirror pairs (the far tails, where f32 derivatives
    underflow, included):

    - the gradient of eval is finite. One forward pass along all the
      parameters at once (each parameter is its value plus T_k t, with one
      shared t and opaque weights T_k = 1): the sum of the derivatives is
      finite exactly when each one is (a NaN or an infinity stays one in
      the sum), and the material's kernel compiles once;
    - for the materials tagged 'plugin' (one per model, anisotropy and
      profile, and the compact disc; in RGB of the gratings a rect,
      RGB_REVERSE_RECT), reverse mode equals forward mode,
      parameter by parameter, summed over the 8,000 lanes: one reverse pass
      (every parameter a leaf), then the same forward kernel once per
      parameter (T_k = 1, the others 0: opaque, so no new kernel). Without
      program.h's broadcast of width-1 live-ins into symbolic if_stmts, a
      grating's period, height, width and coherence length came out
      1,000-3,000 times too large in llvm_ad_rgb here (Adam's normalised
      steps hide it); forward mode was right.

    Gratings: one material per profile (those tagged 'plugin') and, in
    spectral variants, the compact disc (a grating's RGB kernel with every
    parameter differentiated takes 20-40 s to compile; the compact disc's is
    the rect profile's, and the others of the list differ only in numbers)."""
    import stam_materials
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import test_jit
    mi_ = stam_mitsuba.setup(variant)
    wi, wo = test_jit.direction_pairs(8000, seed=3)
    checked, reversed_, failures = 0, 0, []
    rgb_rect = {'name': 'rgb_reverse_rect', 'model': 'periodic', 'tags': ['plugin'],
                'params': RGB_REVERSE_RECT}
    for e in stam_materials.load() + ([rgb_rect] if variant.endswith('_rgb') else []):
        if e['model'] == 'periodic' and ('plugin' not in e['tags'] or (
                e['name'] == 'cd' and variant.endswith('_rgb'))):
            continue
        b = mi_.load_dict({'type': 'diffraction', **stam_materials.plugin_params(e['params'])})
        params = mi_.traverse(b)
        keys = [k for k in params.keys()
                if not params.flags(k) & mi_.ParamFlags.NonDifferentiable.value]
        if not keys:
            continue
        values = {k: float(params[k][0]) for k in keys}
        si, wo_ = test_jit.make_si(wi), mi_.Vector3f(wo.T)

        # Forward mode along sum_k T_k e_k, T_k opaque: one kernel
        def forward(weights):
            t = mi_.Float(0.0)
            dr.enable_grad(t)
            for k in keys:
                params[k] = mi_.Float(values[k]) + dr.opaque(mi_.Float, weights[k]) * t
            params.update()
            v = b.eval(mi_.BSDFContext(), si, wo_)
            dr.forward(t)
            return np.array(dr.grad(v), dtype=np.float64)

        g = forward({k: 1.0 for k in keys})
        assert np.all(np.isfinite(g)), (e['name'], keys, int(np.sum(~np.isfinite(g))))
        checked += len(keys)
        if 'plugin' not in e['tags'] or (variant.endswith('_rgb') and e['model'] == 'periodic'
                                         and e is not rgb_rect):
            # The others differ from these in numbers only (a reverse
            # kernel each would double the test's compile time); of the
            # gratings' RGB programs, whose reverse passes take minutes to
            # compile cold, a rect's (it reads the period, height, width
            # and coherence length in regions): RGB_REVERSE_RECT
            for k in keys:
                params[k] = mi_.Float(values[k])
            params.update()
            continue

        # Reverse mode: every parameter a leaf, one pass
        leaves = {k: mi_.Float(values[k]) for k in keys}
        for k in keys:
            dr.enable_grad(leaves[k])
            params[k] = leaves[k]
        params.update()
        v = b.eval(mi_.BSDFContext(), si, wo_)
        dr.backward(dr.sum(dr.sum(v, axis=0), axis=None))
        reverse = {k: float(dr.grad(leaves[k])[0]) for k in keys}
        for k in keys:
            d = forward({j: float(j == k) for j in keys})
            fwd, scale = float(d.sum()), float(np.abs(d).sum())
            line = '%s %s %s: reverse %.7g, forward %.7g (lanes\' |d| %.4g)' % (
                variant, e['name'], k, reverse[k], fwd, scale)
            print(line)
            if not abs(reverse[k] - fwd) <= REVERSE_FORWARD_TOL * scale:
                failures.append(line)
        for k in keys:
            params[k] = mi_.Float(values[k])
        params.update()
        reversed_ += 1
    assert not failures, failures
    assert reversed_ >= 5
    assert checked >= 10


# A scene of its own (not the plate's above, nor one the gradient fixes
# were developed on): a sphere seen from the side under a point light.
# The stratified sampler without jitter puts a pixel's samples at its
# strata centres, so an RGB image does not depend on the seed, nor on the
# variant: scalar_rgb renders the central differences of rebuilt materials
# natively (no kernel per rebuilt material) at the points llvm_ad_rgb's
# gradient pass sees. Spectral images do depend on the seed (sampled
# wavelengths): there the differences are rendered in the AD variant with
# the seed of the gradient pass.
def sphere_scene(bsdf, res=32):
    T = mi.ScalarTransform4f
    return {
        'type': 'scene',
        'integrator': {'type': 'prb', 'max_depth': 2},
        'sensor': {'type': 'perspective', 'fov': 32,
                   'to_world': T().look_at(origin=[0.0, -4.0, 1.5], target=[0, 0, 0],
                                           up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': res, 'height': res,
                            'rfilter': {'type': 'box'}},
                   'sampler': {'type': 'stratified', 'sample_count': 16, 'jitter': False}},
        'ball': {'type': 'sphere', 'bsdf': bsdf},
        'light': {'type': 'point', 'position': [2.0, -1.5, 3.0],
                  'intensity': {'type': 'spectrum', 'value': 30.0}},
    }


# Steps of the central differences of rebuilt materials, relative (absolute,
# in the parameter's unit, where its value is 0: a twist), by default and
# per material below. Rebuilt tables jitter the image by ~1e-4 relative
# (docs/inverse.md), which a 0.5% step turns into ~2% of a gradient, a 2%
# step into ~0.5%. A grating's period, and a rect's width, move its narrow
# orders across the image or energy between them: the image curves within
# 0.5%, and their steps are smaller (the sine grating's period, scalar_rgb:
# differences 0.1442, 0.1444, 0.1444, 0.090, 0.063 at steps of 0.05%, 0.1%,
# 0.25%, 0.5%, 1%, AD 0.1447; the rect's period, llvm_ad_spectral: -0.0751,
# -0.0756, -0.0785 at 0.05%, 0.1%, 0.25%, AD -0.0750).
REBUILT_STEP_DEFAULT = 0.02
REBUILT_STEP_AT_ZERO = 0.05
REBUILT_TOL = 0.02


@pytest.mark.parametrize('variant', VARIANTS)
@pytest.mark.parametrize('bsdf,steps', [
    ({'surface': 'periodic', 'profile': 'sine', 'period_um': 1.4, 'height_um': 0.18,
      'coherence_um': 5.0, 'fresnel': 0.9}, {'period_um': 0.0025}),
    # Stam's formula: the default's energy table, built anew at each width,
    # moves by more than the width's own effect between rebuilds (the
    # core's RGB eval at 8,000 pairs: central differences of 1e-5, 1e-4 and
    # 1e-3 relative differ lane by lane by 26-62%; the image's by 0.073 to
    # 0.081 for steps of 0.1% to 1%, AD 0.075), which leaves no reference
    # within 2% (docs/inverse.md)
    ({'surface': 'periodic', 'profile': 'rect', 'period_um': 1.8, 'height_um': 0.14,
      'width_um': 0.5, 'coherence_um': 5.0, 'eta': 1.3, 'k': 6.5, 'energy': 'stam'},
     {'period_um': 0.0005, 'width_um': 0.001}),
    ({'surface': 'gaussian', 'sigma_um': 0.11, 'corr_x_um': 0.8, 'corr_y_um': 6.0,
      'twist': 30.0}, {}),
    ({'surface': 'fractal', 'sigma_um': 0.06, 'hurst': 0.7, 'lag_um': 1.2}, {}),
], ids=['sine', 'rect', 'gaussian-aniso', 'fractal'])
def test_render_gradient_equals_rebuilt_central_difference(variant, bsdf, steps):
    """Every differentiable parameter of the material (mi.traverse's), all in
    one prb gradient pass (gratings in RGB: `direct`, the same image): the
    gradient of the sphere image's weighted mean equals
    the central difference of two materials built anew at the parameter's
    value -+ its step (no programs or tables kept), within 2%. RGB: the
    differences in scalar_rgb (the native path), with `direct` (its image
    is prb's under a point light, and prb is an AD variant's)."""
    mi_ = stam_mitsuba.setup(variant)
    full = {'type': 'diffraction', **bsdf}
    rgb = variant.endswith('_rgb')
    d = sphere_scene(full)
    if rgb and bsdf['surface'] == 'periodic':
        # The gratings' RGB gradient kernel through prb (four traced evals
        # with their adjoints) took 4 minutes to compile cold; `direct`
        # renders the same image under the point light (module docstring)
        d['integrator'] = DIRECT
    scene = mi_.load_dict(d)
    params = mi_.traverse(scene)
    keys = [k[len('ball.bsdf.'):] for k in params.keys() if k.startswith('ball.bsdf.')
            and not params.flags(k) & mi_.ParamFlags.NonDifferentiable.value]
    assert keys, list(params.keys())
    x0 = {k: float(params['ball.bsdf.' + k][0]) for k in keys}
    leaves = {k: mi_.Float(x0[k]) for k in keys}
    for k in keys:
        dr.enable_grad(leaves[k])
        params['ball.bsdf.' + k] = leaves[k]
    params.update()
    # The loss weighs the pixels (a fixed random weight per pixel): the
    # image's plain mean hardly moves with a roughness under the default's
    # energy conservation, which only redistributes the light
    res = sphere_scene(full)['sensor']['film']['width']
    weight = np.random.default_rng(5).uniform(0.2, 1.8, (res, res, 1)).repeat(3, axis=2)
    img = mi_.render(scene, params=params, seed=3, seed_grad=SEED)
    dr.backward(dr.mean(img * mi_.TensorXf(weight), axis=None))
    ad = {k: float(dr.grad(leaves[k])[0]) for k in keys}
    del img, params, scene

    fd_mi = stam_mitsuba.setup('scalar_rgb') if rgb else mi_

    def loss_at(k, x):
        d = sphere_scene({**full, k: x})
        if rgb:
            d['integrator'] = DIRECT
        s = fd_mi.load_dict(d)
        if not rgb and bsdf['surface'] == 'periodic':
            # The spectral programs a differentiated parameter selects
            # (exact order weights instead of their table): the same
            # programs as the gradient pass's, built anew at x. A random
            # surface's differentiated programs give its plain ones' values
            # at the built parameters (the energy table read as
            # m + ln(p / p0) dm, with p = p0), without building the
            # table's derivatives (2.8 s for each anisotropic Gaussian)
            p = fd_mi.traverse(s)
            for j in keys:
                leaf = fd_mi.Float(p['ball.bsdf.' + j][0])
                dr.enable_grad(leaf)
                p['ball.bsdf.' + j] = leaf
            p.update()
        img = np.array(dr.detach(fd_mi.render(s, seed=SEED)))
        return float(np.mean(img * weight))

    def central(k, h):
        up, down = loss_at(k, x0[k] + h), loss_at(k, x0[k] - h)
        return (up - down) / (2 * h), up, down

    failures = []
    for k in keys:
        h = (steps.get(k, REBUILT_STEP_DEFAULT) * abs(x0[k]) if x0[k]
             else REBUILT_STEP_AT_ZERO)
        fd, up, down = central(k, h)
        line = '%s %s %s = %g: AD %.6g, central difference of rebuilt materials %.6g' % (
            variant, bsdf['surface'], k, x0[k], ad[k], fd)
        print(line)
        if not abs(up - down) > 1e-5 * abs(up + down):
            failures.append(line + ' (the parameter does not matter here)')
        elif not abs(ad[k] - fd) <= REBUILT_TOL * abs(fd):
            failures.append(line)
    assert not failures, failures
