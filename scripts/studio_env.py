#!/usr/bin/env python3
"""studio_env.py: the procedural studio environment and the compact disc's
label texture used by the hero scenes (scenes/hero_*.xml) and the animations.
Nothing is downloaded: both images are computed here, deterministically.

    .venv/bin/python scripts/studio_env.py      # writes out/env/studio.exr, cd_label.png

studio.exr: a latitude-longitude environment (Mitsuba's envmap convention,
rotated to z-up by the scenes' <rotate x="1" angle="90"/>): a dark studio
(floor 0.01, walls a faint gradient to 0.04) lit by softboxes: two long thin
strip lights behind the subject, one to the side, and a small square key
light. Radiances are in the comments of STRIPS below.

cd_label.png: the printed side of a compact disc in the disk shape's polar
texture coordinates (u = radius / outer radius, v = angle / 2 pi): a white
print with coloured rings and a title that runs around the disc.
"""

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
ENV_DIR = os.path.join(ROOT, 'out', 'env')

# Softboxes in world coordinates (z up; cameras look along +y): (azimuth of
# the centre in degrees, measured from +y towards +x; elevation of the
# centre; half-width in azimuth; half-height in elevation; radiance RGB).
# Width in degrees of the softboxes' edges (a linear falloff).
SOFT = 3.0

STRIPS = [
    (0.0, 45.0, 45.0, 22.0, (0.1, 0.1, 0.11)),     # large dim panel behind (the mirrors' backdrop)
    (-26.0, 32.0, 4.0, 22.0, (11.0, 11.0, 11.0)),    # tall softbox behind, left
    (22.0, 36.0, 4.0, 18.0, (9.5, 9.8, 10.5)),     # tall softbox behind, right
    (0.0, 12.0, 35.0, 1.5, (6.0, 6.0, 5.6)),         # low horizontal strip behind
    (100.0, 45.0, 8.0, 8.0, (8.0, 8.0, 8.0)),        # square side light, right
]


def world_dirs(width):
    """World directions (H, W, 3) of the pixel centres of a lat-long map of
    width x width/2, for Mitsuba's envmap (u = atan2(x, -z) / 2 pi,
    v = acos(y) / pi in the emitter's frame) turned z-up by a rotation of
    +90 degrees about x: world = (x, -z, y)."""
    h = width // 2
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(h) + 0.5) / h
    phi, theta = np.meshgrid(2 * np.pi * u, np.pi * v)
    return np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi),
                     np.cos(theta)], axis=-1)


def studio(width=1024):
    d = world_dirs(width)
    elev = np.degrees(np.arcsin(np.clip(d[..., 2], -1, 1)))
    azim = np.degrees(np.arctan2(d[..., 0], d[..., 1]))
    img = np.empty(d.shape, dtype=np.float32)
    wall = 0.012 + 0.03 * np.clip(elev / 90.0, 0, 1)
    img[...] = np.where(elev < 0, 0.01, wall)[..., None]
    img[..., 2] *= 1.1
    for az, el, haz, hel, rad in STRIPS:
        da = (azim - az + 180.0) % 360.0 - 180.0
        # soft edges (SOFT degrees): smooth falloff, less noise where the disc spreads a light
        wa = np.clip((haz - np.abs(da) * np.cos(np.radians(elev))) / SOFT + 0.5, 0, 1)
        we = np.clip((hel - np.abs(elev - el)) / SOFT + 0.5, 0, 1)
        img += (wa * we)[..., None] * np.asarray(rad, dtype=np.float32)
    return img


def label(size=1024):
    """The printed side in polar uv: rows = angle (v), columns = radius (u)."""
    from PIL import Image, ImageDraw, ImageFont
    u = (np.arange(size) + 0.5) / size
    v = (np.arange(size) + 0.5) / size
    uu, vv = np.meshgrid(u, v)
    img = np.ones((size, size, 3)) * np.array([0.92, 0.91, 0.88])
    ring = lambda a, b: ((uu > a) & (uu < b))[..., None]
    img = np.where(ring(0.0, 0.125), 0.05, img)                  # hole (dark)
    img = np.where(ring(0.125, 0.28), np.array([0.75, 0.77, 0.80]), img)  # clear hub
    img = np.where(ring(0.40, 0.44), np.array([0.85, 0.25, 0.10]), img)
    img = np.where(ring(0.80, 0.86), np.array([0.10, 0.30, 0.70]), img)
    img = np.where(ring(0.97, 1.01), np.array([0.75, 0.77, 0.80]), img)
    im = Image.fromarray((np.clip(img, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8))
    # text along the angle: written in a strip, rotated so it runs along v
    try:
        font = ImageFont.truetype('DejaVuSans-Bold.ttf', 90)
    except OSError:
        try:
            font = ImageFont.truetype('/usr/share/fonts/truetype/dejavu/DejaVuSans-Bold.ttf', 90)
        except OSError:
            font = ImageFont.load_default()
    strip = Image.new('RGB', (size, 130), (235, 233, 228))
    dr = ImageDraw.Draw(strip)
    dr.text((20, 10), 'DIFFRACTION SHADERS  1999', fill=(30, 30, 60), font=font)
    strip = strip.rotate(-90, expand=True).transpose(Image.FLIP_TOP_BOTTOM).resize((int(0.3 * size), size))
    im.paste(strip, (int(0.48 * size), 0))
    return im


def write(out_dir=ENV_DIR, width=1024):
    """Writes studio.exr and cd_label.png into out_dir (if missing or older
    than this script); returns their paths."""
    os.makedirs(out_dir, exist_ok=True)
    env = os.path.join(out_dir, 'studio.exr')
    lab = os.path.join(out_dir, 'cd_label.png')
    me = os.path.getmtime(os.path.abspath(__file__))
    if not (os.path.exists(env) and os.path.getmtime(env) >= me):
        import mitsuba as mi
        if mi.variant() is None:
            mi.set_variant('scalar_rgb')
        tmp = env + '.%d.tmp.exr' % os.getpid()
        mi.Bitmap(studio(width), mi.Bitmap.PixelFormat.RGB).write(tmp)
        os.replace(tmp, env)
    if not (os.path.exists(lab) and os.path.getmtime(lab) >= me):
        tmp = lab + '.%d.tmp.png' % os.getpid()
        label().save(tmp)
        os.replace(tmp, lab)
    return env, lab


if __name__ == '__main__':
    for p in write(sys.argv[1] if len(sys.argv) > 1 else ENV_DIR):
        print(p)
