"""The pip-installable package stam-diffraction (pyproject.toml, python/stam_diffraction).

`make wheel` builds dist/stam_diffraction-*.whl (its size is printed); a fresh
virtualenv outside the repository gets only the pinned mitsuba, drjit and numpy
(from build/wheelhouse/, downloaded once) and the wheel; from a directory outside
the repository it then loads and renders a small scene with the BSDF in
scalar_rgb and llvm_ad_rgb (the package imported before and after
mi.set_variant), and with the `mitsuba` command. A plugin recorded as compiled
against another mitsuba gives the clear error, not a crash. The wheel
describes itself: README.md as its long description, the LICENSE file,
`python -m stam_diffraction --help` listing every surface's parameters with
the core's units, ranges and defaults; no stale advice (-W -W) anywhere.
"""

import json
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'python'))
import stam_diffraction  # noqa: E402

REQUIREMENTS = os.path.join(ROOT, 'scripts', 'requirements.txt')
WHEELHOUSE = os.path.join(ROOT, 'build', 'wheelhouse')
WHEEL_FILES = {'__init__.py', '__main__.py', '_layout.py', 'core.py', 'include/stam.h',
               'libstam.so', 'plugins/diffraction.so', 'plugins/diffraction.abi.json',
               'explore.py', 'explorer/index.html', 'explorer/program.js',
               'explorer/explorer.js'}
WHEEL_MAX_BYTES = 8e6     # the goal is a few MB

SCENE = """\
<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, -3, 3" target="0, 0, 0" up="0, 0, 1"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="24"/><integer name="height" value="24"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle">
        <bsdf type="diffraction">
            <string name="surface" value="gaussian"/>
            <float name="sigma_um" value="0.3"/><float name="corr_um" value="3"/>
        </bsdf>
    </shape>
    <emitter type="point">
        <point name="position" x="0" y="2" z="3"/><rgb name="intensity" value="20"/>
    </emitter>
</scene>
"""

# Run by the fresh venv's Python in the work directory: renders scene.xml in
# each variant of argv[2:], importing stam_diffraction before mi.set_variant
# (argv[1] == 'before') or after it; prints one JSON line.
RENDER = """\
import json, os, sys
if sys.argv[1] == 'before':
    import stam_diffraction
import mitsuba as mi
import numpy as np
out = {}
for v in sys.argv[2:]:
    mi.set_variant(v)
    import stam_diffraction
    img = np.array(mi.render(mi.load_file('scene.xml')))
    out[v] = [float(img.mean()), bool(np.isfinite(img).all())]
from stam_diffraction import core
with core.Brdf({'surface': 'cd'}) as b:
    f = b.eval_rgb([0.0, 0.0, 1.0], [0.3, 0.0, 0.95])
loaded = {}
for v in mi.variants():
    if not v.startswith('cuda'):
        mi.set_variant(v)
        loaded[v] = 'Diffraction[' in str(mi.load_dict({'type': 'diffraction',
                                                       'surface': 'cd'}))
print(json.dumps(dict(renders=out, package=stam_diffraction.__file__,
                      core=core.library_path(), core_rgb=f.tolist(), loaded=loaded,
                      libllvm=os.environ.get('DRJIT_LIBLLVM_PATH'))))
"""


def pins(names):
    """{name: version} of scripts/requirements.txt."""
    with open(REQUIREMENTS) as f:
        found = dict(re.findall(r'^([A-Za-z0-9_.\-]+)==(\S+)', f.read(), re.M))
    return {n: found[n] for n in names}


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    assert r.returncode == 0, '%s failed (%d):\n%s\n%s' % (cmd, r.returncode, r.stdout[-3000:],
                                                          r.stderr[-3000:])
    return r


def wheelhouse():
    """The pinned mitsuba, drjit and numpy wheels, downloaded once."""
    wanted = ['%s==%s' % nv for nv in pins(('mitsuba', 'drjit', 'numpy')).items()]
    have = os.listdir(WHEELHOUSE) if os.path.isdir(WHEELHOUSE) else []
    if not all(any(f.startswith(w.replace('==', '-') + '-') for f in have) for w in wanted):
        run([sys.executable, '-m', 'pip', 'download', '--no-deps', '--only-binary', ':all:',
             '--dest', WHEELHOUSE] + wanted)
    return WHEELHOUSE


@pytest.fixture(scope='module')
def report(request):
    """Prints a line on the terminal as the test runs, past pytest's capture."""
    capture = request.config.pluginmanager.get_plugin('capturemanager')

    def write(line):
        with capture.global_and_fixture_disabled():
            print('\n[wheel] ' + line, flush=True)
    return write


@pytest.fixture(scope='module')
def wheel(report):
    t = time.time()
    run(['make', '--no-print-directory', 'wheel', 'PYTHON=' + sys.executable], cwd=ROOT)
    found = [f for f in os.listdir(os.path.join(ROOT, 'dist')) if f.endswith('.whl')]
    assert len(found) == 1, found
    path = os.path.join(ROOT, 'dist', found[0])
    report('%s: %.2f MB (make wheel %.0f s)' % (found[0], os.path.getsize(path) / 1e6,
                                                time.time() - t))
    return path


@pytest.fixture(scope='module')
def venv(wheel, tmp_path_factory, report):
    """A fresh virtualenv outside the repository with the pinned mitsuba, drjit,
    numpy and the wheel; returns (python, work directory, environment)."""
    t = time.time()
    base = tmp_path_factory.mktemp('wheel')
    env_dir = base / 'venv'
    run([sys.executable, '-m', 'venv', '--without-pip', str(env_dir)])
    python = str(env_dir / 'bin' / 'python')
    run([sys.executable, '-m', 'pip', '--python', python, 'install', '--no-index',
         '--find-links', wheelhouse(), wheel])
    work = base / 'work'
    work.mkdir()
    (work / 'scene.xml').write_text(SCENE)
    env = {k: v for k, v in os.environ.items()
           if k not in ('PYTHONPATH', 'VIRTUAL_ENV', 'DRJIT_LIBLLVM_PATH', 'STAM_CORE_LIB')}
    env['PATH'] = str(env_dir / 'bin') + os.pathsep + env['PATH']
    env['DRJIT_CACHE_DIR'] = str(base / 'drjit-cache')
    report('fresh venv with the wheel: %.0f s' % (time.time() - t))
    return python, str(work), env


def test_wheel_contents_and_size(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    files = {n[len('stam_diffraction/'):] for n in names if n.startswith('stam_diffraction/')}
    assert files == WHEEL_FILES
    assert all(n.startswith(('stam_diffraction/', 'stam_diffraction-')) for n in names)
    assert os.path.getsize(wheel) < WHEEL_MAX_BYTES


def test_pins_agree_with_requirements():
    """pyproject.toml's build requirements and dependencies pin the versions of
    scripts/requirements.txt, with which `make plugin` and `make wheel` build."""
    with open(os.path.join(ROOT, 'pyproject.toml'), 'rb') as f:
        project = tomllib.load(f)
    p = pins(('mitsuba', 'drjit', 'nanobind', 'scikit-build-core'))
    build = set(project['build-system']['requires'])
    deps = set(project['project']['dependencies'])
    for name in ('mitsuba', 'drjit', 'nanobind', 'scikit-build-core'):
        assert '%s==%s' % (name, p[name]) in build
    for name in ('mitsuba', 'drjit'):
        assert '%s==%s' % (name, p[name]) in deps


@pytest.mark.parametrize('order', ['before', 'after'])
def test_render_from_the_installed_wheel(venv, order, report):
    python, work, env = venv
    t = time.time()
    r = run([python, '-c', RENDER, order, 'scalar_rgb', 'llvm_ad_rgb'], cwd=work, env=env)
    res = json.loads(r.stdout.strip().splitlines()[-1])
    site = os.path.dirname(os.path.dirname(python))
    assert res['package'].startswith(site) and res['core'].startswith(site)
    for v in ('scalar_rgb', 'llvm_ad_rgb'):
        mean, finite = res['renders'][v]
        assert finite and mean > 0, (v, res)
    assert max(res['core_rgb']) > 0
    assert all(res['loaded'].values()) and len(res['loaded']) >= 8, res['loaded']
    if order == 'before':
        # the package chose the LLVM library before drjit was imported
        assert res['libllvm'] == stam_diffraction.find_libllvm()
    report('renders with the package imported %s mi.set_variant: %.0f s'
           % (order, time.time() - t))


@pytest.mark.parametrize('variant', ['scalar_rgb', 'llvm_ad_rgb'])
def test_mitsuba_command(venv, variant):
    python, work, env = venv
    plugin_dir = run([python, '-m', 'stam_diffraction', '--plugin-dir'], cwd=work,
                     env=env).stdout.strip()
    assert plugin_dir.startswith(os.path.dirname(os.path.dirname(python)))
    out = os.path.join(work, variant + '.exr')
    # Dr.Jit's default flags (symbolic loops and calls) in every variant
    cmd = ['mitsuba', '-m', variant, '-a', plugin_dir, '-o', out, 'scene.xml']
    if variant.startswith('llvm'):
        env = dict(env, DRJIT_LIBLLVM_PATH=stam_diffraction.find_libllvm())
    run(cmd, cwd=work, env=env)
    check = ('import mitsuba as mi, numpy as np; mi.set_variant("scalar_rgb"); '
             'print(float(np.array(mi.Bitmap(%r)).mean()))' % out)
    assert float(run([python, '-c', check], cwd=work, env=env).stdout) > 0


def test_other_mitsuba_version_is_a_clear_error(venv):
    """The record says mitsuba 3.8.0: importing the package (and the command
    line) fails with both versions named, before the plugin is loaded."""
    python, work, env = venv
    site_pkg = run([python, '-c', 'import sysconfig; print(sysconfig.get_paths()["platlib"])'],
                   cwd=work, env=env).stdout.strip()
    record = os.path.join(site_pkg, 'stam_diffraction', 'plugins', 'diffraction.abi.json')
    saved = record + '.saved'
    shutil.copy(record, saved)
    try:
        with open(record) as f:
            compiled = json.load(f)
        with open(record, 'w') as f:
            json.dump(dict(compiled, mitsuba='3.8.0'), f)
        installed = pins(('mitsuba', 'drjit'))
        for args in (['-c', 'import stam_diffraction'],
                     ['-m', 'stam_diffraction', '--plugin-dir']):
            r = subprocess.run([python] + args, capture_output=True, text=True, cwd=work,
                               env=env)
            assert r.returncode == 1, (r.returncode, r.stderr)
            last = r.stderr.strip().splitlines()[-1]
            assert last.startswith('stam_diffraction.VersionMismatchError: '), last
            assert 'mitsuba 3.8.0 and drjit %s' % installed['drjit'] in last, last
            assert 'mitsuba %s and drjit %s' % (installed['mitsuba'], installed['drjit']) in last
            assert 'mitsuba==3.8.0' in last
    finally:
        os.replace(saved, record)
    run([python, '-c', 'import stam_diffraction'], cwd=work, env=env)


def test_the_wheel_describes_itself(wheel):
    """The metadata's long description is README.md (markdown), the license
    is MIT with the LICENSE file in the wheel, and it claims no address the
    project does not have."""
    with zipfile.ZipFile(wheel) as z:
        info = [n for n in z.namelist() if '.dist-info/' in n]
        metadata = z.read([n for n in info if n.endswith('/METADATA')][0]).decode()
        licenses = [n for n in info if n.endswith('/licenses/LICENSE')]
        assert licenses, info
        license_text = z.read(licenses[0]).decode()
    head, _, body = metadata.partition('\n\n')
    assert 'Description-Content-Type: text/markdown' in head, head
    assert 'License-Expression: MIT' in head and 'License-File: LICENSE' in head, head
    assert 'Project-URL' not in head, head     # no public address yet
    with open(os.path.join(ROOT, 'README.md')) as f:
        readme = f.read()
    assert body.strip() == readme.strip()
    with open(os.path.join(ROOT, 'LICENSE')) as f:
        assert f.read() == license_text
    assert license_text.startswith('MIT License')
    assert 'Copyright (c) 2026 the stam-diffraction authors' in license_text


def test_help_lists_every_parameter_from_the_core():
    """`python -m stam_diffraction --help` lists every key of every surface
    of the core's parameter reference (stam_parameter_reference) with its
    unit, accepted range and default, and the plugin's own keys."""
    from stam_diffraction import __main__ as cli, core
    text = cli.parameter_help()
    env = dict(os.environ, PYTHONPATH=os.path.join(ROOT, 'python'))
    out = run([sys.executable, '-m', 'stam_diffraction', '--help'], env=env).stdout
    assert ' '.join(text.split()) in ' '.join(out.split())
    ref = core.parameter_reference()
    sections = [('Every surface:', ref['material'])] + \
        [('surface "%s":' % s['surface'], s['keys']) for s in ref['surfaces']]
    flat = ' '.join(text.split())
    for i, (title, keys) in enumerate(sections):
        start = flat.index(title)
        end = flat.index(sections[i + 1][0]) if i + 1 < len(sections) else len(flat)
        part = flat[start:end]
        for d in keys:
            unit = ' (%s)' % d['unit'] if d['unit'] else ''
            entry = part.index('%s%s: %s' % (d['key'], unit, ' '.join(d['meaning'].split())))
            facts = part[entry:]
            assert facts.index('accepted ' + ' '.join(d['accepted'].split())) < 400, d
            if d['required']:
                assert '; required' in facts[:400], d
            elif d['default'] is not None:
                assert 'default ' + cli._value(d['default']) in facts[:500], d
    for key in ('twist (degrees)', 'tracks:', 'center_u, center_v', 'eta, k'):
        assert key in flat, key
    # The compact disc's defaults, as a user would look for them
    cd = flat[flat.index('surface "cd":'):]
    for words in ('period_um (um): grating period (track pitch) accepted [0.05, 1000]; '
                  'default 2.5', 'default 50', 'default 0.15', 'default 0.5', 'default "rect"'):
        assert words in cd, words


def test_no_stale_flag_advice():
    """The default Dr.Jit flags work (and are faster): nothing advises -W -W
    (symbolic loops and calls off) any more."""
    env = dict(os.environ, PYTHONPATH=os.path.join(ROOT, 'python'))
    out = run([sys.executable, '-m', 'stam_diffraction'], env=env).stdout
    assert '-W' not in out and '--help' in out, out
    places = [os.path.join(ROOT, 'README.md')]
    for folder, ext in (('docs', '.md'), ('python/stam_diffraction', '.py'),
                        ('mitsuba-plugin', ''), ('scripts', '.py')):
        for name in os.listdir(os.path.join(ROOT, folder)):
            if name.endswith(ext) and os.path.isfile(os.path.join(ROOT, folder, name)):
                places.append(os.path.join(ROOT, folder, name))
    for path in places:
        with open(path, errors='replace') as f:
            text = f.read()
        assert not re.search(r'-W -W|add `?-W|`-W` given twice', text), path


def test_installed_package_lists_the_parameters(venv):
    """The installed wheel alone reaches the parameter reference."""
    python, work, env = venv
    out = run([python, '-m', 'stam_diffraction', '--help'], cwd=work, env=env).stdout
    assert 'surface "cd":' in out and 'period_um (um)' in out and 'default 2.5' in out, out


def test_version_check_in_process():
    """check_versions() against a fake record, and the real one (no error)."""
    installed = stam_diffraction.installed_versions()
    with pytest.raises(stam_diffraction.VersionMismatchError) as e:
        stam_diffraction.check_versions(dict(installed, drjit='1.4.0'))
    msg = str(e.value)
    assert 'drjit 1.4.0' in msg and 'drjit %s' % installed['drjit'] in msg
    assert isinstance(e.value, ImportError)
    with pytest.raises(stam_diffraction.VersionMismatchError, match='not installed'):
        stam_diffraction.check_versions(installed, dict(installed, mitsuba=None))
    stam_diffraction.check_versions()
    assert stam_diffraction.compiled_versions() == installed


def test_find_libllvm_takes_the_newest_supported(tmp_path):
    for name in ('lib/libLLVM-15.so', 'lib/libLLVM.so.19.1', 'lib/libLLVMSupport.so',
                 'llvm-18/lib/libLLVM.so', 'llvm-21/lib/libLLVMX86CodeGen.a'):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text('')
    patterns = (str(tmp_path / 'lib' / 'libLLVM[.-]*'),
                str(tmp_path / 'llvm-*' / 'lib' / 'libLLVM[.-]*'))
    find = stam_diffraction.find_libllvm
    assert find(patterns=patterns) == str(tmp_path / 'lib' / 'libLLVM.so.19.1')
    assert find(min_major=19, patterns=patterns[1:]) is None
    assert find(min_major=18, patterns=patterns[1:]) == str(tmp_path / 'llvm-18/lib/libLLVM.so')
