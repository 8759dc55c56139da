"""What a new user of the `diffraction` plugin trips over, tested:

- tracks on real shapes: concentric tracks circle the centre of a disk, a
  rectangle and a uv-mapped mesh alike (the periodic direction is radial in
  space), linear tracks run straight on all three (on the disk, whose uv is
  polar, along its object x axis); a mesh without texture coordinates is
  refused with an error naming the problem;
- parameters: a tabulated profile in each documented form, NaN and Inf
  heights refused by name, unknown keys listed with the plugin's own keys
  and the closest one, metal spellings, the twist's range, k without eta;
- plausibility warnings: logged once per material and shown by str();
- mi.traverse updates are transactional (a refused update leaves the
  material as it was, and later updates work) and carry string parameters;
  mi.traverse exposes every parameter, the core's defaults included, with
  the flags of a written one, and changing a default works.

The oracle for the frames is the core itself (stam_diffraction.core): at a
point whose periodic direction is expected along the world vector d, the
plugin's eval must equal the core's f at the directions rotated into the
frame whose x axis is d, times cos theta_o.

Run: make core plugin && .venv/bin/python -m pytest tests/test_plugin_usability.py
"""

import json
import math
import os
import re
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

CD = {'surface': 'cd'}
GAUSSIAN = {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_um': 2.0}
# Broad, strongly anisotropic lobes: the frame tests see the tracks'
# direction at any outgoing direction (a grating's orders are too narrow to
# hit at random); x is the tracks' periodic direction as for gratings.
BRUSHED = {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_x_um': 0.5, 'corr_y_um': 5.0}
# A local incident direction and outgoing directions around the first order
WI = np.array([0.3, 0.2, math.sqrt(1 - 0.13)])


def use(variant):
    return stam_mitsuba.setup(variant)


def to_np(x):
    return np.array(x, dtype=np.float64)


def outgoing(n=24, seed=5):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.2
    return v / np.linalg.norm(v, axis=1)[:, None]


# ---------------------------------------------------------------------------
# Tracks on real shapes
# ---------------------------------------------------------------------------

SQUARE_OBJ = """v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
{vt}f 1{a} 2{b} 3{c}
f 1{a} 3{c} 4{d}
"""


def write_square(path, with_uv):
    vt = 'vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n' if with_uv else ''
    marks = ('/1', '/2', '/3', '/4') if with_uv else ('', '', '', '')
    with open(path, 'w') as f:
        f.write(SQUARE_OBJ.format(vt=vt, a=marks[0], b=marks[1], c=marks[2], d=marks[3]))
    return path


def shape_scene(shape):
    return mi.load_dict({'type': 'scene', 'shape': shape})


def is_scalar():
    return mi.variant().startswith('scalar')


def hits(scene, points):
    """Surface interactions of rays straight down onto the z = const plane
    of the shapes at the world points' (x, y): one per point in scalar
    variants, one vectorised interaction otherwise."""
    p = np.asarray(points, dtype=np.float64)
    if is_scalar():
        sis = [scene.ray_intersect(mi.Ray3f(mi.Point3f(q[0], q[1], 10.0), mi.Vector3f(0, 0, -1)))
               for q in p]
        assert all(si.is_valid() for si in sis), 'a ray missed the shape'
        return sis
    o = mi.Point3f(p[:, 0], p[:, 1], np.full(len(p), 10.0))
    si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0, 0, -1)))
    assert dr.all(si.is_valid()), 'a ray missed the shape'
    return [si]


def rows(x):
    """A Mitsuba 3-vector (scalar or vectorised) as (n, 3)."""
    return to_np(x).reshape(3, -1).T


def plugin_eval(bsdf, sis, wo_local):
    """Plugin eval (n, 3) and the shading frames' s and t (n, 3) at the
    interactions, with wi = WI."""
    got, fs, ft = [], [], []
    for si in sis:
        si.wi = mi.Vector3f(WI)
        got.append(rows(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo_local))))
        fs.append(rows(si.sh_frame.s))
        ft.append(rows(si.sh_frame.t))
    return np.concatenate(got), np.concatenate(fs), np.concatenate(ft)


def expected_eval(params, frame_s, frame_t, wo_local, direction_world):
    """The core's f * cos at the local directions rotated into the frame
    whose x axis is the world vector `direction_world` (per lane)."""
    d = np.asarray(direction_world, dtype=np.float64)
    a = np.arctan2(np.sum(d * frame_t, axis=1), np.sum(d * frame_s, axis=1))
    c, s = np.cos(a)[:, None], np.sin(a)[:, None]

    def rot(v):
        return np.concatenate([c * v[:, :1] + s * v[:, 1:2], -s * v[:, :1] + c * v[:, 1:2],
                               v[:, 2:]], axis=1)
    n = len(a)
    wi = np.broadcast_to(WI, (n, 3))
    wo = np.broadcast_to(wo_local, (n, 3))
    with stam_core.Brdf(params) as b:
        return b.eval_rgb(rot(wi), rot(wo)) * wo[:, 2:3]


def check_directions(variant, shape, points, params, extra, direction):
    """Plugin eval at the points == core eval in the frame whose x axis is
    direction(p) (world), for several outgoing directions. `shape`: a
    function giving the shape's dict (after the variant is set)."""
    use(variant)
    shape = shape()
    bsdf = mi.load_dict({'type': 'diffraction', **params, **extra})
    scene = shape_scene(dict(shape, bsdf=bsdf))
    p = np.asarray(points, dtype=np.float64)
    d = np.array([direction(q) for q in p])
    d_wrong = np.stack([-d[:, 1], d[:, 0], d[:, 2]], axis=1)   # d turned 90 degrees
    checked, sensitive = 0, 0
    for wo in outgoing(8):
        got, fs, ft = plugin_eval(bsdf, hits(scene, p), wo)
        ref = expected_eval(params, fs, ft, wo, d)
        assert np.allclose(got, ref, rtol=2e-3, atol=1e-6), (got, ref)
        checked += np.sum(ref > 1e-2 * ref.max())
        wrong = expected_eval(params, fs, ft, wo, d_wrong)
        sensitive += np.sum(np.abs(wrong - ref) > 0.1 * np.abs(ref) + 1e-6)
    assert checked >= 24    # the directions saw the lobes
    assert sensitive > 20   # and a frame turned by 90 degrees would fail


def disk_transform():
    return mi.ScalarTransform4f().translate([1.0, 2.0, 0.5]).rotate([0, 0, 1], 30).scale(2.0)


POINTS_DISK = [[1.0 + 1.2, 2.0 + 0.3, 0], [1.0 - 0.5, 2.0 + 1.1, 0],
               [1.0 + 0.2, 2.0 - 1.6, 0], [1.0 - 1.3, 2.0 - 0.4, 0]]
POINTS_RECT = [[-1 + 2.0, 0.7, 0], [-1 - 2.5, -1.1, 0], [-1 + 0.4, 1.3, 0], [-1 - 0.8, 0.2, 0]]
POINTS_MESH = [[3.6, 1.3, 0], [2.5, 0.3, 0], [3.1, 1.8, 0], [2.2, 1.5, 0]]


def radial_from(centre):
    return lambda p: np.array([p[0] - centre[0], p[1] - centre[1], 0.0])


VARIANTS = ['scalar_rgb', 'llvm_ad_rgb']


@pytest.mark.parametrize('variant', VARIANTS)
def test_concentric_tracks_on_a_disk_circle_its_centre(variant):
    """The disk's uv is polar; its concentric tracks still circle its
    centre (translated, rotated and scaled by to_world)."""
    def shape():
        return {'type': 'disk', 'to_world': disk_transform()}
    check_directions(variant, shape, POINTS_DISK, BRUSHED, {'tracks': 'concentric'},
                     radial_from([1.0, 2.0]))


@pytest.mark.parametrize('variant', VARIANTS)
def test_concentric_tracks_on_a_disk_with_a_centre(variant):
    """center_u/center_v on a disk: the point (2u - 1, 2v - 1) of its
    object space (the same square a rectangle's uv covers)."""
    use(variant)
    t = disk_transform()
    centre = np.array(t @ mi.ScalarPoint3f(2 * 0.7 - 1, 2 * 0.4 - 1, 0))
    def shape():
        return {'type': 'disk', 'to_world': t}
    check_directions(variant, shape, POINTS_DISK, BRUSHED,
                     {'tracks': 'concentric', 'center_u': 0.7, 'center_v': 0.4},
                     radial_from(centre))


@pytest.mark.parametrize('variant', VARIANTS)
def test_linear_tracks_on_a_disk_are_straight(variant):
    """tracks = linear on a disk: along its object x axis (rotated 30
    degrees here), not along its polar uv's radial dp/du."""
    def shape():
        return {'type': 'disk', 'to_world': disk_transform()}
    a = math.radians(30)
    check_directions(variant, shape, POINTS_DISK, BRUSHED, {},
                     lambda p: np.array([math.cos(a), math.sin(a), 0.0]))
    # twist rotates them like anywhere else
    b = math.radians(30 + 45)
    check_directions(variant, shape, POINTS_DISK, BRUSHED, {'twist': 45.0},
                     lambda p: np.array([math.cos(b), math.sin(b), 0.0]))


@pytest.mark.parametrize('variant', VARIANTS)
def test_concentric_tracks_on_a_stretched_rectangle_circle_its_centre(variant):
    """A non-uniformly scaled rectangle: the tracks are circles in space
    (radial = p - centre), not ellipses of its uv."""
    def shape():
        return {'type': 'rectangle', 'to_world':
                mi.ScalarTransform4f().translate([-1.0, 0.0, 0.0]).scale([3.0, 1.5, 1.0])}
    check_directions(variant, shape, POINTS_RECT, BRUSHED, {'tracks': 'concentric'},
                     radial_from([-1.0, 0.0]))
    check_directions(variant, shape, POINTS_RECT, BRUSHED, {},
                     lambda p: np.array([1.0, 0.0, 0.0]))


@pytest.mark.parametrize('variant', VARIANTS)
def test_concentric_tracks_on_a_uv_mapped_mesh_circle_its_uv_centre(variant, tmp_path):
    obj = write_square(str(tmp_path / 'square_uv.obj'), with_uv=True)
    def shape():
        return {'type': 'obj', 'filename': obj,
                'to_world': mi.ScalarTransform4f().translate([3.0, 1.0, 0.0])}
    check_directions(variant, shape, POINTS_MESH, BRUSHED, {'tracks': 'concentric'},
                     radial_from([3.0, 1.0]))


@pytest.mark.parametrize('variant', VARIANTS)
@pytest.mark.parametrize('tracks', ['linear', 'concentric'])
def test_tracks_on_a_mesh_without_uv_are_refused(variant, tracks, tmp_path):
    use(variant)
    obj = write_square(str(tmp_path / 'square.obj'), with_uv=False)
    bsdf = mi.load_dict({'type': 'diffraction', **CD, 'tracks': tracks})
    scene = shape_scene({'type': 'obj', 'filename': obj, 'bsdf': bsdf})
    si = hits(scene, np.array(POINTS_MESH) - [3.0, 1.0, 0.0])
    with pytest.raises(Exception) as e:
        plugin_eval(bsdf, si, outgoing(1)[0])
    msg = str(e.value)
    assert 'diffraction' in msg and 'texture coordinates' in msg and tracks in msg, msg
    # An isotropic material ignores the frame: no error
    iso = mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'tracks': tracks})
    scene = shape_scene({'type': 'obj', 'filename': obj, 'bsdf': iso})
    si = hits(scene, np.array(POINTS_MESH) - [3.0, 1.0, 0.0])
    assert np.all(np.isfinite(plugin_eval(iso, si, outgoing(1)[0])[0]))


@pytest.mark.parametrize('variant', VARIANTS)
def test_meshes_are_judged_each_time(variant, tmp_path):
    """Scenes built and freed in turn, with and without uv, the same BSDF
    object: a freed mesh's address may be reused, so nothing about a mesh
    may be remembered by address."""
    use(variant)
    with_uv = write_square(str(tmp_path / 'uv.obj'), with_uv=True)
    without = write_square(str(tmp_path / 'plain.obj'), with_uv=False)
    bsdf = mi.load_dict({'type': 'diffraction', **CD, 'tracks': 'concentric'})
    points = np.array(POINTS_MESH) - [3.0, 1.0, 0.0]
    for _ in range(3):
        scene = shape_scene({'type': 'obj', 'filename': with_uv, 'bsdf': bsdf})
        assert np.all(np.isfinite(plugin_eval(bsdf, hits(scene, points), outgoing(1)[0])[0]))
        del scene
        scene = shape_scene({'type': 'obj', 'filename': without, 'bsdf': bsdf})
        with pytest.raises(Exception, match='texture coordinates'):
            plugin_eval(bsdf, hits(scene, points), outgoing(1)[0])
        del scene


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_render_of_a_mesh_without_uv_raises_the_error(variant, tmp_path):
    use(variant)
    obj = write_square(str(tmp_path / 'square.obj'), with_uv=False)
    scene = mi.load_dict({
        'type': 'scene', 'integrator': {'type': 'direct'},
        'sensor': {'type': 'perspective', 'fov': 60,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -2, 3], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   'film': {'type': 'hdrfilm', 'width': 8, 'height': 8}},
        'shape': {'type': 'obj', 'filename': obj,
                  'bsdf': {'type': 'diffraction', **CD, 'tracks': 'concentric'}},
        'light': {'type': 'point', 'position': [0, 2, 3]}})
    with pytest.raises(Exception) as e:
        mi.render(scene, spp=1)
    msgs, err = [], e.value
    while err is not None:
        msgs.append(str(err))
        err = err.__cause__ or err.__context__
    assert any('texture coordinates' in m for m in msgs), msgs


def render_disc(shape, bsdf, spp=16):
    """A small oblique render of a disc under a point light."""
    scene = mi.load_dict({
        'type': 'scene', 'integrator': {'type': 'direct'},
        'sensor': {'type': 'perspective', 'fov': 40,
                   'to_world': mi.ScalarTransform4f().look_at(origin=[0, -5, 6], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   'sampler': {'type': 'independent', 'sample_count': spp},
                   'film': {'type': 'hdrfilm', 'width': 48, 'height': 48,
                            'rfilter': {'type': 'box'}}},
        'disc': dict(shape, bsdf=bsdf),
        'light': {'type': 'point', 'position': [0.5, 6, 6],
                  'intensity': {'type': 'spectrum', 'value': 100.0}}})
    return to_np(mi.render(scene, seed=3))


def test_a_disk_and_a_rectangle_give_the_same_disc():
    """The look of the disc: a disk and a rectangle of the same size with
    concentric tracks render the same image where both are (the disk's
    area), and linear tracks on the disk do not."""
    use('scalar_rgb')
    scale = mi.ScalarTransform4f().scale(2.0)
    disk = {'type': 'disk', 'to_world': scale}
    rect = {'type': 'rectangle', 'to_world': scale}
    # Broad orders (short coherence) so that 16 spp resolve them
    cd = {'type': 'diffraction', **CD, 'coherence_um': 5.0, 'tracks': 'concentric'}
    mask = render_disc(disk, {'type': 'diffuse'}, spp=4).sum(axis=2) > 0
    inside = mask & np.roll(mask, 1, 0) & np.roll(mask, -1, 0) & \
        np.roll(mask, 1, 1) & np.roll(mask, -1, 1)           # no edge pixels
    a = render_disc(disk, cd)[inside]
    b = render_disc(rect, cd)[inside]
    c = render_disc(disk, dict(cd, tracks='linear'))[inside]
    assert inside.sum() > 300 and a.max() > 0
    # Same seed, same geometry inside the disk: equal up to float rounding
    assert np.abs(a - b).sum() < 0.02 * a.sum()
    assert np.abs(a - c).sum() > 0.3 * a.sum()


# ---------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------

PERIODIC = {'surface': 'periodic', 'period_um': 2.0, 'coherence_um': 20.0}


def error_of(params, variant='scalar_rgb'):
    use(variant)
    with pytest.raises(Exception) as e:
        mi.load_dict({'type': 'diffraction', **params})
    return str(e.value)


def eval_at(bsdf, wo=(-0.35, 0.1, 0.93)):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(WI)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.8, 0.6)
    si.dp_du = mi.Vector3f(1, 0, 0)
    si.dp_dv = mi.Vector3f(0, 1, 0)
    w = np.array(wo) / np.linalg.norm(wo)
    return to_np(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(w)))


@pytest.mark.parametrize('variant', VARIANTS)
def test_profile_in_each_documented_form(variant):
    use(variant)
    forms = ['0, 0.1, 0.25, 0.1', '[0, 0.1, 0.25, 0.1]', '{"heights_um": [0, 0.1, 0.25, 0.1]}',
             ' { "heights_um" : [0,0.1,0.25,0.1] } ']
    values = [eval_at(mi.load_dict({'type': 'diffraction', **PERIODIC, 'profile': f}))
              for f in forms]
    for v in values[1:]:
        assert np.array_equal(v, values[0])
    with stam_core.Brdf({**PERIODIC, 'profile': {'heights_um': [0, 0.1, 0.25, 0.1]}}) as b:
        assert b.flags() & stam_core.FLAG_ANISOTROPIC


@pytest.mark.parametrize('profile,why', [
    ('0,nan', 'NaN'), ('0, 0.1, inf', 'infinite'), ('nan, 0.1', 'NaN'),
    ('[0, 0.1', "end with ']'"), ('{"heights": [0, 0.1]}', 'heights_um'),
    ('0, 0.1, abc', 'comma-separated'), ('', 'empty')])
def test_bad_profiles_are_refused_by_name(profile, why):
    msg = error_of({**PERIODIC, 'profile': profile})
    assert "parameter 'profile'" in msg and why in msg, msg
    assert 'heights_um' in msg, msg     # the accepted forms are listed
    assert 'JSON' not in msg, msg       # no parser message without a name


def test_unknown_profile_name_lists_the_forms():
    msg = error_of({**PERIODIC, 'profile': 'triangle'})
    assert "'profile'" in msg and 'rect' in msg and 'sine' in msg, msg


@pytest.mark.parametrize('variant', VARIANTS)
def test_unknown_key_lists_every_accepted_key_and_the_closest(variant):
    msg = error_of({**GAUSSIAN, 'twistt': 10.0}, variant)
    assert "unknown parameter 'twistt'" in msg, msg
    accepted = msg[msg.index('(accepted: ') + 11:msg.index(')')]
    keys = [k.strip() for k in accepted.split(',')]
    for k in ('surface', 'fresnel', 'sigma_um', 'corr_um', 'twist', 'tracks', 'center_u',
              'center_v', 'eta', 'k'):
        assert k in keys, (k, msg)
    assert "did you mean 'twist'?" in msg, msg
    msg = error_of({**CD, 'period': 1.6}, variant)
    assert "did you mean 'period_um'?" in msg, msg
    msg = error_of({**CD, 'quux': 1.0}, variant)
    assert 'did you mean' not in msg and 'twist' in msg, msg


def test_metal_spellings():
    use('scalar_rgb')
    ref = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'fresnel': 'aluminium'}))
    for name in ('aluminum', 'al', 'Al'):
        v = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'fresnel': name}))
        assert np.array_equal(v, ref), name


@pytest.mark.parametrize('params,name', [
    ({**CD, 'twist': 1e9}, 'twist'),
    ({**CD, 'twist': -361.0}, 'twist'),
    ({**CD, 'k': 3.0}, "'k' needs 'eta' (the complex index eta + i k; eta in [0.001, 100])"),
    ({**CD, 'tracks': 'radial'}, 'tracks'),
])
def test_plugin_parameters_refused_by_name(params, name):
    msg = error_of(params)
    assert 'diffraction' in msg and name in msg, msg


def test_twist_of_a_full_turn_is_accepted_and_eta_alone_is_a_dielectric():
    use('scalar_rgb')
    a = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'twist': 360.0}))
    b = eval_at(mi.load_dict({'type': 'diffraction', **CD}))
    assert np.allclose(a, b, rtol=1e-5, atol=1e-9)
    a = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'eta': 1.5}))
    b = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'eta': 1.5, 'k': 0.0}))
    assert np.array_equal(a, b)


# ---------------------------------------------------------------------------
# Plausibility warnings
# ---------------------------------------------------------------------------

class Capture(mi.Appender if hasattr(mi, 'Appender') else object):
    def __init__(self):
        super().__init__()
        self.lines = []

    def append(self, level, text):
        if level == mi.LogLevel.Warn:
            self.lines.append(text)

    def log_progress(self, *args):
        pass


@pytest.fixture
def log():
    use('scalar_rgb')
    cap = Capture()
    logger = mi.logger() if hasattr(mi, 'logger') else mi.Thread.thread().logger()
    logger.add_appender(cap)
    yield cap
    logger.remove_appender(cap)


def test_implausible_values_are_logged_once(log):
    b = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 100.0,
                      'corr_um': 1000.0})
    ours = [line for line in log.lines if 'diffraction' in line]
    assert len(ours) == 1, log.lines
    assert "'sigma_um'" in ours[0] and 'nanometres' in ours[0], ours
    assert 'warnings' in str(b) and 'Beckmann' in str(b)
    # An update that keeps the warning does not log it again, ...
    params = mi.traverse(b)
    params['twist'] = 20.0
    params.update()
    assert len([line for line in log.lines if 'diffraction' in line]) == 1
    # ... one that changes it does (the quoted alpha = 2 sigma / T changes) ...
    params['corr_um'] = 900.0
    params.update()
    assert len([line for line in log.lines if 'diffraction' in line]) == 2
    # ... and one that removes it leaves none in str()
    params['sigma_um'] = 0.03
    params['corr_um'] = 1.0
    params.update()
    assert 'warnings' not in str(b)


def test_plausible_materials_log_nothing(log):
    for params in (CD, GAUSSIAN, {'surface': 'fractal', 'sigma_um': 0.05, 'hurst': 0.5,
                                  'lag_um': 1.0}):
        b = mi.load_dict({'type': 'diffraction', **params})
        assert 'warnings' not in str(b)
    assert not [line for line in log.lines if 'diffraction' in line], log.lines


# ---------------------------------------------------------------------------
# mi.traverse: transactional updates, string parameters
# ---------------------------------------------------------------------------

def number(v):
    """A traversed number: a float (scalar variants) or a one-value Float
    (JIT variants, as Mitsuba's own BSDFs expose theirs)."""
    return float(v[0]) if hasattr(v, '__len__') else float(v)


def refused(params, match):
    with pytest.raises(Exception) as e:
        params.update()
    msg = str(e.value)
    assert match in msg and 'keeps its previous parameters' in msg, msg


@pytest.mark.parametrize('variant', VARIANTS)
def test_refused_update_leaves_the_material_as_it_was(variant):
    use(variant)
    b = mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'twist': 10.0})
    before, text = eval_at(b), str(b)
    params = mi.traverse(b)
    params['sigma_um'] = -1.0
    refused(params, 'sigma_um')
    assert number(params['sigma_um']) == pytest.approx(0.1)
    assert str(b) == text
    assert np.array_equal(eval_at(b), before)
    # Two changes, one bad: neither is taken
    params['corr_um'] = 3.0
    params['twist'] = 1e9
    refused(params, 'twist')
    assert number(params['corr_um']) == pytest.approx(2.0)
    assert number(params['twist']) == pytest.approx(10.0)
    assert str(b) == text and np.array_equal(eval_at(b), before)
    # Later updates work
    params['sigma_um'] = 0.2
    params.update()
    assert 'sigma_um = 0.2' in str(b) or 'sigma_um = 0.200000003' in str(b)
    after = eval_at(b)
    fresh = eval_at(mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'sigma_um': 0.2,
                                  'twist': 10.0}))
    assert np.allclose(after, fresh, rtol=1e-6) and not np.allclose(after, before)


@pytest.mark.parametrize('variant', VARIANTS)
def test_string_parameters_change_through_traverse(variant):
    use(variant)
    b = mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'fresnel': 'silver'})
    params = mi.traverse(b)
    assert params['fresnel'].plugin_name() == 'silver'
    assert params['surface'].plugin_name() == 'gaussian'
    assert params['tracks'].plugin_name() == 'linear'
    params['fresnel'] = 'gold'
    params.update()
    gold = eval_at(mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'fresnel': 'gold'}))
    assert np.array_equal(eval_at(b), gold)
    assert params['fresnel'].plugin_name() == 'gold'
    params['fresnel'] = 'unobtainium'
    refused(params, 'fresnel')
    assert params['fresnel'].plugin_name() == 'gold'
    assert np.array_equal(eval_at(b), gold)


@pytest.mark.parametrize('variant', VARIANTS)
def test_tracks_and_profile_change_through_traverse(variant):
    use(variant)
    b = mi.load_dict({'type': 'diffraction', **CD})
    params = mi.traverse(b)
    params['tracks'] = 'concentric'
    params.update()
    conc = eval_at(mi.load_dict({'type': 'diffraction', **CD, 'tracks': 'concentric'}))
    assert np.array_equal(eval_at(b), conc)
    assert mi.has_flag(b.flags(), mi.BSDFFlags.Anisotropic)
    params['tracks'] = 'spiral'
    refused(params, 'tracks')
    assert params['tracks'].plugin_name() == 'concentric'

    g = mi.load_dict({'type': 'diffraction', **PERIODIC, 'profile': '0, 0.1'})
    params = mi.traverse(g)
    params['profile'] = '[0, 0.2, 0.1]'
    params.update()
    ref = eval_at(mi.load_dict({'type': 'diffraction', **PERIODIC, 'profile': '0, 0.2, 0.1'}))
    assert np.array_equal(eval_at(g), ref)
    params['profile'] = '0, nan'
    refused(params, 'profile')
    assert params['profile'].plugin_name() == '[0, 0.2, 0.1]'
    assert np.array_equal(eval_at(g), ref)


# ---------------------------------------------------------------------------
# mi.traverse: every parameter, defaults included
# ---------------------------------------------------------------------------

def value_of(params, key):
    v = params[key]
    return v.plugin_name() if hasattr(v, 'plugin_name') else number(v)


# Materials with defaults, and the same with every default written out
WITH_DEFAULTS = [
    (CD, dict(CD, period_um=2.5, coherence_um=50.0, profile='rect', height_um=0.15,
              width_um=0.5, fresnel='aluminium', energy='conserving')),
    (GAUSSIAN, dict(GAUSSIAN, series_tolerance=1e-5, rgb_nodes=12, fresnel='aluminium',
                    energy='conserving')),
    (dict(BRUSHED, eta=1.5), dict(BRUSHED, eta=1.5, k=0.0, series_tolerance=1e-5, rgb_nodes=12,
                                  energy='conserving')),
    (dict(PERIODIC, profile='sine', height_um=0.2),
     dict(PERIODIC, profile='sine', height_um=0.2, fresnel='aluminium', energy='conserving')),
]


@pytest.mark.parametrize('variant', VARIANTS)
@pytest.mark.parametrize('given,written', WITH_DEFAULTS)
def test_traverse_exposes_every_parameter_with_the_flags_of_a_written_one(variant, given,
                                                                          written):
    """The keys left at their defaults are exposed with the core's values
    (stam_brdf_params_json) and the flags they have when written (in the
    AD variants differentiable exactly where the programs read them); the
    core is built from the user's keys alone."""
    use(variant)
    b = mi.load_dict({'type': 'diffraction', **given})
    params = mi.traverse(b)
    full = mi.traverse(mi.load_dict({'type': 'diffraction', **written}))
    assert set(params.keys()) == set(full.keys()), (params.keys(), full.keys())
    for key in full.keys():
        assert params.flags(key) == full.flags(key), key
        assert value_of(params, key) == pytest.approx(value_of(full, key)), key
    core_params = {k: v for k, v in given.items() if k not in ('eta', 'k')}
    if 'eta' in given:
        core_params['fresnel'] = {'eta': given['eta']}
    with stam_core.Brdf(core_params) as core:
        resolved = core.resolved_params()
    for key, value in resolved.items():
        if isinstance(value, dict):         # a complex index: the plugin's eta and k
            for part, x in value.items():
                assert value_of(params, part) == pytest.approx(x), part
        elif key != 'gradients':
            assert value_of(params, key) == pytest.approx(value), key
    # The core is built from the user's keys alone
    core_json = json.loads(re.search(r'core_json = (\{.*\}),', str(b)).group(1))
    assert core_json == core_params, str(b)


@pytest.mark.parametrize('variant', VARIANTS)
def test_defaults_change_through_traverse(variant):
    """params['period_um'] of a compact disc that left it at its default,
    docs/guide.md's params['fresnel'] = 'gold' with fresnel left at its
    default: the material is then the one with those values written; a
    default that follows another key follows it (the disc's bump width is
    at most its period); a refused default keeps its value."""
    use(variant)
    b = mi.load_dict({'type': 'diffraction', **CD})
    params = mi.traverse(b)
    params['period_um'] = 2.0
    params.update()
    assert np.array_equal(eval_at(b), eval_at(mi.load_dict({'type': 'diffraction', **CD,
                                                            'period_um': 2.0})))
    params['fresnel'] = 'gold'
    params.update()
    gold = {'type': 'diffraction', **CD, 'period_um': 2.0, 'fresnel': 'gold'}
    assert np.array_equal(eval_at(b), eval_at(mi.load_dict(gold)))
    assert params['fresnel'].plugin_name() == 'gold'
    params['period_um'] = 0.4
    params.update()
    assert number(params['width_um']) == pytest.approx(0.4)    # at most the period
    assert np.array_equal(eval_at(b), eval_at(mi.load_dict(dict(gold, period_um=0.4))))
    params['height_um'] = -1.0
    refused(params, 'height_um')
    assert number(params['height_um']) == pytest.approx(0.15)
    assert np.array_equal(eval_at(b), eval_at(mi.load_dict(dict(gold, period_um=0.4))))
    # A Gaussian's defaults: fresnel (the guide's example), rgb_nodes
    g = mi.load_dict({'type': 'diffraction', **GAUSSIAN})
    params = mi.traverse(g)
    params['fresnel'] = 'gold'
    params['rgb_nodes'] = 16
    params.update()
    ref = mi.load_dict({'type': 'diffraction', **GAUSSIAN, 'fresnel': 'gold', 'rgb_nodes': 16})
    assert np.array_equal(eval_at(g), eval_at(ref))


def test_a_default_moved_within_the_drift_is_kept_by_later_rebuilds():
    """JIT variants: a default moved by under 2% keeps the programs (the
    value reaches them from memory); a later rebuild builds the core with
    it."""
    use('llvm_ad_rgb')
    b = mi.load_dict({'type': 'diffraction', **CD})
    params = mi.traverse(b)
    params['period_um'] = 2.5 * 1.01
    params.update()
    assert 'core_json = {"surface": "cd"}' in str(b), str(b)     # no rebuild
    params['energy'] = 'stam'
    params.update()
    assert '"period_um": 2.52' in str(b), str(b)
    ref = mi.load_dict({'type': 'diffraction', **CD, 'period_um': 2.525, 'energy': 'stam'})
    assert np.allclose(eval_at(b), eval_at(ref), rtol=1e-6)


@pytest.mark.parametrize('variant', VARIANTS)
def test_missing_uv_message_names_no_tracks_the_user_did_not_set(variant, tmp_path):
    """An anisotropic material without `tracks` on a mesh without uv: the
    error says what is missing without naming a tracks value the user never
    wrote."""
    use(variant)
    obj = write_square(str(tmp_path / 'square.obj'), with_uv=False)
    bsdf = mi.load_dict({'type': 'diffraction', **CD})
    scene = shape_scene({'type': 'obj', 'filename': obj, 'bsdf': bsdf})
    si = hits(scene, np.array(POINTS_MESH) - [3.0, 1.0, 0.0])
    with pytest.raises(Exception) as e:
        plugin_eval(bsdf, si, outgoing(1)[0])
    msg = str(e.value)
    assert 'texture coordinates' in msg and 'anisotropic' in msg, msg
    assert 'tracks = "linear"' not in msg, msg


@pytest.mark.parametrize('variant', ['llvm_ad_rgb', 'llvm_ad_spectral'])
def test_calls_with_python_numbers_reuse_their_kernels(variant):
    """bsdf.eval, pdf and sample called from Python with Python numbers (a
    loop over directions, one at a time) compile their kernels once: the
    plugin puts such literals in memory, where Dr.Jit would have folded each
    value into a kernel of its own (a compact disc's RGB eval: 0.8 s per
    call before, 5 ms after; docs/guide.md). Checked by the kernels'
    hashes (Dr.Jit's kernel history), not by time."""
    use(variant)
    b = mi.load_dict({'type': 'diffraction', 'surface': 'gaussian', 'sigma_um': 0.1,
                      'corr_um': 2.0, 'fresnel': 'gold'})
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(0.5, 0.5)
    si.dp_du, si.dp_dv = mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0)
    ctx = mi.BSDFContext()

    def kernels(k):
        si.wi = mi.Vector3f(0.3 + 0.01 * k, 0.1, 0.9)
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(450.0 + k, 520.0, 590.0, 660.0 - k)
        wo = mi.Vector3f(-0.3 + 0.02 * k, 0.1 - 0.01 * k, 0.9)
        dr.kernel_history()  # clears it
        dr.eval(b.eval(ctx, si, wo), b.pdf(ctx, si, wo),
                b.sample(ctx, si, 0.1 + 0.1 * k, mi.Point2f(0.3, 0.6 - 0.1 * k)))
        return {e['hash'] for e in dr.kernel_history() if e['type'] == dr.KernelType.JIT}

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = kernels(0)
        later = kernels(1) | kernels(2)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert first and later <= first, (first, later)
