"""stam_images: small image helpers shared by render_gallery.py and compare.py.

Linear float images (H, W, 3) -> 8-bit sRGB PNG, float32 EXR through Mitsuba's
Bitmap, and a labelled contact sheet (PIL).
"""

import os

import numpy as np
from PIL import Image, ImageDraw, ImageFont


def srgb_encode(x):
    """Linear -> sRGB transfer curve, clipped to [0, 1]."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_srgb8(img, exposure=1.0):
    """Linear RGB (H, W, 3 or 1) -> uint8 sRGB, multiplied by `exposure` first."""
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    return (srgb_encode(img[..., :3] * exposure) * 255.0 + 0.5).astype(np.uint8)


def auto_exposure(img, percentile=99.5, target=0.9):
    """Exposure that maps the given percentile of the brightest channel to `target`."""
    m = np.asarray(img)[..., :3].max(axis=-1)
    p = np.percentile(m, percentile) if m.size else 0.0
    return target / p if p > 0 else 1.0


def save_png(path, img, exposure=1.0):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    Image.fromarray(to_srgb8(img, exposure)).save(path)


def save_exr(mi, path, img):
    """Float32 linear RGB EXR through mitsuba.Bitmap (needs a variant set)."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    arr = np.ascontiguousarray(np.asarray(img, dtype=np.float32)[..., :3])
    mi.Bitmap(arr, mi.Bitmap.PixelFormat.RGB).write(path)


def _font(size):
    for name in ('DejaVuSans.ttf', '/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf'):
        try:
            return ImageFont.truetype(name, size)
        except OSError:
            pass
    return ImageFont.load_default()


def contact_sheet(path, items, columns=4, tile=256, title=None):
    """items: list of (label, PNG path). Writes one labelled PNG."""
    rows = (len(items) + columns - 1) // columns
    label_h, title_h, pad = 38, (36 if title else 0), 6
    sheet = Image.new('RGB', (columns * (tile + pad) + pad,
                              title_h + rows * (tile + label_h + pad) + pad), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    f_label, f_title = _font(13), _font(18)
    if title:
        draw.text((pad, 8), title, fill=(235, 235, 235), font=f_title)
    for n, (label, png) in enumerate(items):
        r, c = divmod(n, columns)
        x = pad + c * (tile + pad)
        y = title_h + pad + r * (tile + label_h + pad)
        im = Image.open(png).convert('RGB')
        im.thumbnail((tile, tile))
        sheet.paste(im, (x + (tile - im.width) // 2, y + (tile - im.height) // 2))
        for k, line in enumerate(label.split('\n')[:2]):
            draw.text((x + 2, y + tile + 3 + 16 * k), line, fill=(235, 235, 235), font=f_label)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    sheet.save(path)
