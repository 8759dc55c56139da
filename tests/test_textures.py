"""Texturable parameters of the `diffraction` BSDF (issue 14): a twist map.

`twist` takes any Mitsuba texture (degrees, unbounded): the tracks turn by
the texture's value at each point, in every variant. Other parameters refuse
a texture with a message naming them. In the AD variants the texture's
values are differentiable (mi.traverse: twist.<its parameters>).

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


def eval_at(mi, bsdf, uv):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(0.3, 0.2, math.sqrt(1 - 0.13))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    si.uv = mi.Point2f(*uv)
    if mi.is_spectral:
        si.wavelengths = [450.0, 520.0, 590.0, 660.0]
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(-0.1, -0.5, math.sqrt(0.74))),
                    dtype=np.float64).ravel()


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
        mi.load_dict({**BRUSHED, 'sigma_um': {'type': 'uniform', 'value': 0.1}})
    assert "'sigma_um' cannot take a texture" in str(e.value), str(e.value)


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_twist_map_values_are_differentiable(variant):
    """d(mean of a render)/d(the map's value) against a central difference,
    with the same samples (tests/test_gradients.py's method)."""
    mi = stam_mitsuba.setup(variant)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import test_gradients as tg
    bsdf = {**BRUSHED, 'twist': {'type': 'uniform', 'value': 25.0}}
    scene = mi.load_dict(tg.scene_dict(bsdf))
    params = mi.traverse(scene)
    key = 'plate.bsdf.twist.value'
    assert key in params and params.flags(key) & mi.ParamFlags.NonDifferentiable.value == 0
    h, values = 2.0, []
    for x in (25.0 + h, 25.0 - h):
        params[key] = mi.Float(x)
        params.update()
        values.append(tg.mean_of(scene))
    fd = (values[0] - values[1]) / (2 * h)
    v = mi.Float(25.0)
    dr.enable_grad(v)
    params[key] = v
    params.update()
    img = mi.render(scene, params=params, seed=1, seed_grad=tg.SEED, spp=16)
    dr.backward(dr.mean(img, axis=None))
    ad = float(dr.grad(v)[0])
    assert abs(fd) > 1e-4 * max(values)
    assert abs(ad - fd) <= tg.GRADIENT_TOL * abs(fd), (ad, fd)
