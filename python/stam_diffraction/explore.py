"""python -m stam_diffraction.explore [--port N] [--no-browser]

A live material explorer in the browser (docs/explorer.md). It serves a page on
the loopback address and opens it (or prints its address): the material on a
disc, a sphere and a flat patch seen from above, under a small movable light
and two strip lights, with a control for every parameter of the chosen
surface model (ranges, units and defaults from the core's parameter
reference), an RGB/spectral switch, and the Mitsuba XML and Python dict of
the current material, ready to paste.

The page computes nothing of the BRDF itself. For each material it asks this
server for the core's exported programs (stam_brdf_export_program: op lists
and the tables they read, through stam_diffraction.core) and translates them,
with a generic translator of the op list (explorer/program.js), into a WebGL2
fragment shader. A parameter that the programs read at run time (their Param
operation: a grating's period, height, width and coherence length) moves a
uniform at once; the server rebuilds the material when it moves further than
the programs follow (STAM_PROGRAM_MAX_DRIFT) and for every other parameter.

Endpoints (JSON): GET /api/contract (the program format, from stam.h),
GET /api/reference (the parameter reference, the plugin's frame keys, the
presets), POST /api/material {"params": {...}, "mode": "rgb" | "spectral",
"wavelengths": N} (the programs as base64 float32, the resolved parameters,
warnings, the mi.load_dict dict, from which the page writes the XML; 400 with the core's message for a bad
material), POST /api/result and GET /api/result (what a page in test mode
read back from its float framebuffer).
"""

import argparse
import base64
import functools
import json
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.parse
import webbrowser
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

from . import core

PAGE_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'explorer')
STATIC = {'/': 'index.html', '/index.html': 'index.html', '/program.js': 'program.js',
          '/explorer.js': 'explorer.js'}
TYPES = {'.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8'}

# The plugin's frame keys (mitsuba-plugin/diffraction.cpp), which the page
# applies as geometry, as the plugin does; the core never sees them.
FRAME_KEYS = [
    {'key': 'twist', 'unit': 'deg', 'min': -360.0, 'max': 360.0, 'default': 0.0,
     'meaning': 'rotation of the tracks (the tangent frame) about the normal'},
    {'key': 'tracks', 'accepted': ['linear', 'concentric'], 'default': 'linear',
     'meaning': 'straight tracks along the shape\'s u direction, or circles about '
                'the centre (a compact disc)'},
]

# Starting materials, one per surface model (values of docs/guide.md).
PRESETS = {
    'gaussian': {'surface': 'gaussian', 'sigma_um': 0.03, 'corr_um': 1.0,
                 'fresnel': 'aluminium'},
    'fractal': {'surface': 'fractal', 'sigma_um': 0.02, 'hurst': 0.7, 'lag_um': 1.0,
                'fresnel': 'silver'},
    'periodic': {'surface': 'periodic', 'period_um': 1.6, 'profile': 'sine', 'height_um': 0.12,
                 'coherence_um': 6.0, 'fresnel': 'gold'},
    'cd': {'surface': 'cd'},
    'heightmap': {'surface': 'heightmap', 'file': 'scenes/heightmaps/gaussian.npy',
                  'pixel_um': 0.08},
}
# The presets' frame: concentric tracks for the disc, straight ones else.
PRESET_FRAMES = {'cd': {'tracks': 'concentric', 'twist': 0.0}}

# Program kinds per mode: what the page executes.
MODE_PROGRAMS = {
    'rgb': {'eval': core.PROGRAM_EVAL_RGB, 'coherent': core.PROGRAM_COHERENT_RGB},
    'spectral': {'eval': core.PROGRAM_EVAL_SPECTRAL, 'coherent': core.PROGRAM_COHERENT_SPECTRAL},
}
WAVELENGTHS_NM = (360.0, 830.0)
# Debian's Chromium, headless, WebGL2 through SwiftShader (tests, pictures).
CHROMIUM = ('chromium', '--headless', '--no-sandbox', '--use-gl=angle', '--use-angle=swiftshader',
            '--enable-unsafe-swiftshader', '--window-size=900,700', '--remote-debugging-port=0')
MAX_WAVELENGTHS = 64


def contract():
    """The program format the page's translator reads (stam.h, through core)."""
    return {'format': core.PROGRAM_FORMAT, 'header_len': core.PROGRAM_HEADER_LEN,
            'ops': {name: code for code, name in enumerate(core.PROGRAM_OPS)},
            'params': list(core.PROGRAM_PARAMS),
            'max_drift': core.PROGRAM_MAX_DRIFT}


def height_maps(root):
    """The height maps under root/scenes/heightmaps (`make heightmaps`), as
    the page offers them: paths relative to root."""
    folder = os.path.join(root, 'scenes', 'heightmaps')
    if not os.path.isdir(folder):
        return []
    return sorted(os.path.relpath(os.path.join(folder, f), root) for f in os.listdir(folder)
                  if f.endswith(('.npy', '.exr', '.tif', '.tiff', '.png', '.csv')))


def reference(root='.'):
    """The parameter reference of the core, the frame keys, the presets and
    the height maps found under root."""
    return {'core': core.parameter_reference(), 'frame': FRAME_KEYS, 'presets': PRESETS,
            'preset_frames': PRESET_FRAMES, 'height_maps': height_maps(root)}


@functools.lru_cache(maxsize=None)
def spectral_weights(n):
    """n wavelengths (the midpoints of n equal bins of 360-830 nm) and their
    linear sRGB weights (n, 3): the CIE 1931 observer under D65, as Mitsuba's
    film converts a spectral render, normalised so that a reflectance of 1
    at every wavelength gives (1, 1, 1). From Mitsuba's own CIE tables;
    computed once per n (read-only arrays)."""
    import mitsuba as mi
    lo, hi = WAVELENGTHS_NM
    lam = lo + (np.arange(n) + 0.5) * (hi - lo) / n
    before = mi.variant()
    mi.set_variant('scalar_spectral')
    try:
        xyz = np.array([list(mi.cie1931_xyz(float(x))) for x in lam], dtype=np.float64)
        d65 = mi.load_dict({'type': 'd65'})
        si = mi.SurfaceInteraction3f()
        illum = []
        for x in lam:
            si.wavelengths = [float(x)] * 4
            illum.append(float(d65.eval(si)[0]))
        xyz *= np.array(illum)[:, None]
        # Mitsuba's own XYZ -> linear sRGB
        rgb = np.array([list(mi.xyz_to_srgb(mi.Color3f(*c))) for c in xyz])
    finally:
        if before:
            mi.set_variant(before)
    rgb /= rgb.sum(axis=0, keepdims=True)
    lam.setflags(write=False)
    rgb.setflags(write=False)
    return lam, rgb


def _program_b64(brdf, kind):
    p = brdf.export_program(kind)
    if p is None:
        return None
    return base64.b64encode(np.ascontiguousarray(p, dtype='<f4').tobytes()).decode()


def mitsuba_props(params, frame):
    """The material as Mitsuba's properties: (name, kind, value) in order,
    kind one of 'string', 'float', 'integer', 'boolean'. A complex fresnel
    becomes the plugin's eta and k; a tabulated profile its string form."""
    props = [('surface', 'string', params['surface'])]
    for key, value in params.items():
        if key == 'surface':
            continue
        if key == 'fresnel' and isinstance(value, dict):
            props.append(('eta', 'float', float(value['eta'])))
            if 'k' in value:
                props.append(('k', 'float', float(value['k'])))
        elif key == 'profile' and isinstance(value, dict):
            props.append(('profile', 'string',
                          ' '.join(repr(float(h)) for h in value['heights_um'])))
        elif isinstance(value, bool):
            props.append((key, 'boolean', value))
        elif isinstance(value, str):
            props.append((key, 'string', value))
        elif isinstance(value, (int, float)):
            # A key the reference calls an integer is one; JSON's 1 for a
            # length is a float
            if key in _integer_keys():
                props.append((key, 'integer', int(value)))
            else:
                props.append((key, 'float', float(value)))
        elif key == 'gradients' and isinstance(value, list):
            props.append((key, 'string', ','.join(value)))
        else:
            raise ValueError('stam_diffraction.explore: no Mitsuba form for %s = %r'
                             % (key, value))
    if float(frame.get('twist', 0.0)) != 0.0:
        props.append(('twist', 'float', float(frame['twist'])))
    if frame.get('tracks', 'linear') != 'linear':
        props.append(('tracks', 'string', frame['tracks']))
    return props


@functools.lru_cache(maxsize=None)
def _integer_keys():
    """The keys the core's reference calls integers (read once)."""
    ref = core.parameter_reference()
    docs = ref['material'] + [k for s in ref['surfaces'] for k in s['keys']]
    return {d['key'] for d in docs if d['integer']}


def mitsuba_dict(params, frame):
    """The material as the dict of mi.load_dict."""
    d = {'type': 'diffraction'}
    for name, _, value in mitsuba_props(params, frame):
        d[name] = value
    return d


def _path_for_core(params, root):
    """A heightmap's file relative to the server's root, as the core opens it."""
    p = dict(params)
    if 'file' in p and not os.path.isabs(p['file']):
        p['file'] = os.path.join(root, p['file'])
    return p


def build_material(params, mode='rgb', wavelengths=16, frame=None, root='.'):
    """The page's material: the core's programs for `mode` and the rest the
    page shows. Raises ValueError with the core's message on a bad material."""
    if mode not in MODE_PROGRAMS:
        raise ValueError('stam_diffraction.explore: mode is "rgb" or "spectral", not %r' % mode)
    frame = frame or {}
    start = time.perf_counter()
    with core.Brdf(_path_for_core(params, root)) as b:
        programs = {name: _program_b64(b, kind) for name, kind in MODE_PROGRAMS[mode].items()}
        resolved = b.resolved_params()
        warnings = b.warnings()
    out = {'programs': programs, 'resolved': resolved, 'warnings': warnings,
           'dict': mitsuba_dict(params, frame),
           'build_s': time.perf_counter() - start, 'mode': mode}
    if mode == 'spectral':
        n = int(wavelengths)
        if not 1 <= n <= MAX_WAVELENGTHS:
            raise ValueError('stam_diffraction.explore: wavelengths is in [1, %d], not %d'
                             % (MAX_WAVELENGTHS, n))
        lam, w = spectral_weights(n)
        out['wavelengths_nm'] = lam.tolist()
        out['rgb_weights'] = w.tolist()
        # The weights' density per nm (1 nm steps), for frames whose
        # wavelengths shift within their bins: the same normalisation
        lo, hi = WAVELENGTHS_NM
        fine, wf = spectral_weights(int(hi - lo))
        out['band_nm'] = [lo, hi]
        out['density_from_nm'] = float(fine[0])
        out['rgb_density'] = (wf / (fine[1] - fine[0])).tolist()
    return out


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):
        # A browser that closes its connection (a closed tab, a test that
        # stops its browser) is not an error of the server's.
        if not isinstance(sys.exc_info()[1], (ConnectionError, BrokenPipeError)):
            super().handle_error(request, client_address)


class Explorer:
    """The explorer's server: serve() in a thread, url, results, stop()."""

    def __init__(self, port=0, root=None):
        self.root = os.path.abspath(root or os.getcwd())
        self.results = {}
        self.result_event = threading.Condition()
        self.httpd = _Server(('127.0.0.1', port), self._handler())
        self.thread = None

    @property
    def url(self):
        return 'http://127.0.0.1:%d/' % self.httpd.server_address[1]

    def start(self):
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()
        return self

    def stop(self):
        self.httpd.shutdown()
        self.httpd.server_close()

    def wait_result(self, name, timeout):
        """The result the page posted under `name`, or None after timeout s."""
        with self.result_event:
            self.result_event.wait_for(lambda: name in self.results, timeout)
            return self.results.get(name)

    def run_headless(self, query, timeout=240):
        """Loads the page with `query` (a dict; its 'test' names the result)
        in a headless Chromium of its own and returns what the page posted,
        or None after timeout s; the browser is stopped either way."""
        url = self.url + '?' + urllib.parse.urlencode(query)
        proc = subprocess.Popen(CHROMIUM + (url,), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            return self.wait_result(query['test'], timeout)
        finally:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    def _handler(self):
        explorer = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _send(self, code, body, ctype='application/json'):
                data = body if isinstance(body, bytes) else json.dumps(body).encode()
                self.send_response(code)
                self.send_header('Content-Type', ctype)
                self.send_header('Content-Length', str(len(data)))
                self.send_header('Cache-Control', 'no-store')
                self.end_headers()
                self.wfile.write(data)

            def do_GET(self):
                path = self.path.split('?')[0]
                if path in STATIC:
                    name = STATIC[path]
                    with open(os.path.join(PAGE_DIR, name), 'rb') as f:
                        self._send(200, f.read(), TYPES[os.path.splitext(name)[1]])
                elif path == '/api/contract':
                    self._send(200, contract())
                elif path == '/api/reference':
                    self._send(200, reference(explorer.root))
                elif path == '/api/result':
                    self._send(200, explorer.results)
                else:
                    self._send(404, {'error': 'no such page: %s' % path})

            def do_POST(self):
                path = self.path.split('?')[0]
                n = int(self.headers.get('Content-Length', 0))
                try:
                    body = json.loads(self.rfile.read(n) or b'{}')
                except ValueError as e:
                    return self._send(400, {'error': 'not JSON: %s' % e})
                if path == '/api/material':
                    try:
                        self._send(200, build_material(
                            body.get('params', {}), body.get('mode', 'rgb'),
                            body.get('wavelengths', 16), body.get('frame'), explorer.root))
                    except (ValueError, KeyError, TypeError) as e:
                        self._send(400, {'error': str(e)})
                elif path == '/api/result':
                    with explorer.result_event:
                        explorer.results[body.get('name', 'result')] = body
                        explorer.result_event.notify_all()
                    self._send(200, {'ok': True})
                else:
                    self._send(404, {'error': 'no such endpoint: %s' % path})

        return Handler


def main(argv=None):
    ap = argparse.ArgumentParser(prog='python -m stam_diffraction.explore',
                                 description='A live material explorer in the browser '
                                             '(docs/explorer.md).')
    ap.add_argument('--port', type=int, default=8765,
                    help='port on 127.0.0.1 (0: any free one; default 8765)')
    ap.add_argument('--no-browser', action='store_true',
                    help='print the address instead of opening a browser')
    ap.add_argument('--root', default=None,
                    help='folder that relative height-map files are read from '
                         '(default: the current one)')
    args = ap.parse_args(argv)
    ex = Explorer(args.port, args.root).start()
    print('stam_diffraction explorer: %s (Ctrl-C stops it)' % ex.url, flush=True)
    if not args.no_browser:
        webbrowser.open(ex.url)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        ex.stop()
    return 0


if __name__ == '__main__':
    sys.exit(main())
