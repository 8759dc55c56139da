"""The explorer's pictures and frame times (docs/explorer.md).

Starts the explorer's server, loads its page in headless Chromium (software
WebGL2: SwiftShader) in test mode for each surface model's preset, and
writes docs/img/explorer/<model>.png (the page's three views side by side,
tone-mapped as the page does: exposure 1, the sRGB curve) and prints each
view's time for one whole picture at the size asked for. Those times are a
software renderer's on this machine's CPU, not a GPU's.

    .venv/bin/python scripts/explorer_shots.py [--res 256] [--strips 3] [--out docs/img/explorer]
        [--models cd,periodic] [--mode spectral]

Spectral pictures are the mean of 8 frames (the page's wavelengths shifted
within their bins, as it does while it is left to converge); the times are
one frame's.
"""

import argparse
import base64
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'python'))

from stam_diffraction import explore  # noqa: E402

VIEWS = ('sphere', 'disc', 'patch')


def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def shoot(server, name, params, frame, res, strips, mode='rgb'):
    query = {'material': json.dumps(params), 'frame': json.dumps(frame), 'views': ','.join(VIEWS),
             'view': VIEWS[0], 'mode': mode, 'res': res, 'strips': strips, 'test': name,
             'wavelengths': 16, 'frames': 8}
    r = server.run_headless(query, 1800)
    if r is None or 'error' in r:
        raise RuntimeError('%s: %s' % (name, r and r.get('error')))
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--res', type=int, default=256)
    ap.add_argument('--strips', type=int, default=3)
    ap.add_argument('--out', default=os.path.join(ROOT, 'docs', 'img', 'explorer'))
    ap.add_argument('--models', default=','.join(explore.PRESETS))
    ap.add_argument('--mode', default='rgb')
    args = ap.parse_args()
    import imageio.v3 as iio
    os.makedirs(args.out, exist_ok=True)
    server = explore.Explorer(0, root=ROOT).start()
    try:
        for model in args.models.split(','):
            params = explore.PRESETS[model]
            frame = dict({'tracks': 'linear', 'twist': 0.0}, **explore.PRESET_FRAMES.get(model, {}))
            r = shoot(server, model, params, frame, args.res, args.strips, args.mode)
            tiles = []
            for view in VIEWS:
                v = r['views'][view]
                img = np.frombuffer(base64.b64decode(v['radiance']), dtype='<f4').reshape(
                    args.res, args.res, 4)[::-1, :, :3]
                tiles.append((srgb(img) * 255 + 0.5).astype(np.uint8))
                print('%s %s %s: %d px, %d passes, one picture %.2f s (software WebGL: %s); '
                      'shader compile %.1f s, %d operations'
                      % (model, args.mode, view, args.res, v['passes'], v['frame_ms'] / 1e3,
                         r['renderer'], r['compile_ms'] / 1e3, r['ops']), flush=True)
            path = os.path.join(args.out, '%s%s.png' % (model, '' if args.mode == 'rgb'
                                                       else '_' + args.mode))
            iio.imwrite(path, np.concatenate(tiles, axis=1))
            print('wrote', os.path.relpath(path, ROOT), flush=True)
    finally:
        server.stop()


if __name__ == '__main__':
    main()
