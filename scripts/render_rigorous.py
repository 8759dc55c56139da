"""render_rigorous: the compact disc of scenes/cd.xml under the same light with
each order's power from Stam's formula (`"energy": "stam"`), from the
energy-conserving formula (the Kirchhoff default) and from Maxwell's
equations (`"orders": "rigorous"`), side by side (docs/rigorous.md, "In a
material").

    python scripts/render_rigorous.py [--scene scenes/hero_cd.xml]
        [--variant scalar_spectral] [--res 256] [--spp 64] [--out docs/rigorous_render.png]

The hero scene needs its studio environment (out/env/, made by
scripts/studio_env.py, which the gallery and `make demo` run).

Prints each render's time and the image's mean linear RGB. The rigorous
table is built on the first run (seconds, progress on stderr) and kept on
disk (STAM_CACHE_DIR).
"""

import argparse
import os
import re
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import stam_mitsuba  # noqa: E402
import stam_images  # noqa: E402

SCENE = os.path.join(stam_mitsuba.PROJECT_DIR, 'scenes', 'hero_cd.xml')


# (label, the disc's extra string parameters)
MODES = [
    ('stam', {'energy': 'stam'}),
    ('conserving', {}),
    ('rigorous', {'orders': 'rigorous'}),
]


def scene_text(scene, extra):
    """The scene's text with the disc's extra string parameters."""
    with open(scene) as f:
        text = f.read()
    line = '<string name="surface" value="cd"/>'
    assert line in text
    lines = ''.join('\n            <string name="%s" value="%s"/>' % kv for kv in extra.items())
    return text.replace(line, line + lines)


def render(mi, scene, label, extra, res, spp):
    # Beside the scene, so that its relative paths hold.
    path = os.path.join(os.path.dirname(os.path.abspath(scene)), '.rigorous_%s.xml' % label)
    with open(path, 'w') as f:
        f.write(scene_text(scene, extra))
    try:
        loaded = mi.load_file(path, res=res, spp=spp)
    finally:
        os.remove(path)
    start = time.time()
    image = np.array(mi.render(loaded))[..., :3]
    return image, time.time() - start


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--scene', default=SCENE)
    ap.add_argument('--variant', default='scalar_spectral')
    ap.add_argument('--res', type=int, default=256)
    ap.add_argument('--spp', type=int, default=64)
    ap.add_argument('--out', default=os.path.join(stam_mitsuba.PROJECT_DIR, 'docs',
                                                  'rigorous_render.png'))
    args = ap.parse_args()
    mi = stam_mitsuba.setup(args.variant)
    images = []
    for label, extra in MODES:
        image, seconds = render(mi, args.scene, label, extra, args.res, args.spp)
        mean = image.reshape(-1, 3).mean(axis=0)
        print('%-10s %s %dx%d %d spp: %.1f s, mean linear RGB %s'
              % (label, args.variant, args.res, args.res, args.spp, seconds,
                 np.array2string(mean, precision=4)))
        images.append(image)
    # One exposure for all: the rigorous image's.
    exposure = stam_images.auto_exposure(images[-1])
    gap = np.full((args.res, 4, 3), 1.0 / exposure)
    row = [images[0]]
    for image in images[1:]:
        row += [gap, image]
    stam_images.save_png(args.out, np.concatenate(row, axis=1), exposure)
    print('wrote', args.out, '(left to right: %s)' % ', '.join(m[0] for m in MODES))


if __name__ == '__main__':
    main()
