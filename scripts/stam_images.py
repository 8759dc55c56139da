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


def _wrap(draw, text, font, width):
    """Greedy word wrap of one line of text to `width` pixels."""
    out, cur = [], ''
    for word in text.split(' '):
        trial = (cur + ' ' + word).strip()
        if cur and draw.textlength(trial, font=font) > width:
            out.append(cur)
            cur = word
        else:
            cur = trial
    if cur:
        out.append(cur)
    return out


def contact_sheet(path, items, columns=4, tile=256, title=None, font_size=14):
    """items: list of (label, PNG path). Writes one labelled PNG: each image
    fitted into a tile x tile cell (aspect kept), its label word-wrapped to the
    cell's width below it, every row as tall as its longest label."""
    pad, line_h = 8, font_size + 5
    f_label, f_title = _font(font_size), _font(18)
    probe = ImageDraw.Draw(Image.new('RGB', (1, 1)))
    wrapped = []
    for label, _ in items:
        lines = []
        for para in label.split('\n'):
            lines += _wrap(probe, para, f_label, tile - 4)
        wrapped.append(lines)
    rows = (len(items) + columns - 1) // columns
    row_h = [tile + 6 + line_h * max(len(w) for w in wrapped[r * columns:(r + 1) * columns])
             for r in range(rows)]
    title_lines = _wrap(probe, title, f_title, columns * (tile + pad) - pad) if title else []
    title_h = 26 * len(title_lines) + (8 if title else 0)
    sheet = Image.new('RGB', (columns * (tile + pad) + pad,
                              title_h + sum(row_h) + pad * (rows + 1)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    for k, line in enumerate(title_lines):
        draw.text((pad, 8 + 26 * k), line, fill=(235, 235, 235), font=f_title)
    for n, ((label, png), lines) in enumerate(zip(items, wrapped)):
        r, c = divmod(n, columns)
        x = pad + c * (tile + pad)
        y = title_h + pad + sum(row_h[:r]) + pad * r
        im = Image.open(png).convert('RGB')
        im.thumbnail((tile, tile), Image.LANCZOS)
        sheet.paste(im, (x + (tile - im.width) // 2, y + (tile - im.height) // 2))
        for k, line in enumerate(lines):
            draw.text((x + 2, y + tile + 4 + line_h * k), line, fill=(235, 235, 235),
                      font=f_label)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    sheet.save(path)
