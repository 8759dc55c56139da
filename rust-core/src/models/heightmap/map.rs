//! Reading a height map: NumPy's .npy (the format of scientific Python and
//! of most AFM/profilometer exporters' scripts), OpenEXR (Mitsuba's and
//! the renderers' image format, through the `exr` crate), TIFF (floats or
//! integers: Gwyddion's and profilometers' export; the `tiff` crate), 16-
//! or 8-bit gray PNG (the `png` crate) and plain CSV, then the
//! heights detrended (mean and tilt removed: a tilted sample is a tilted
//! mirror, not a rougher surface).
//!
//! The .npy reader is the format's version 1-3 header (a Python dict
//! literal) and a C- or Fortran-ordered 2-D array of little- or big-endian
//! floats or integers: about sixty lines, where a crate would add its
//! dependency tree to every build of the core.

use crate::error::StamError;

/// Smallest and largest edge of a map, in samples.
pub const MIN_EDGE: usize = 16;
pub const MAX_EDGE: usize = 4096;

/// A height map: heights in micrometres, row-major with rows along y.
#[derive(Clone, Debug)]
pub struct HeightField {
    pub nx: usize,
    pub ny: usize,
    pub pixel_um: f64,
    pub heights_um: Vec<f64>,
}

impl HeightField {
    /// The map of `values` (rows along y) scaled to micrometres, checked
    /// (finite, within the size limits) and detrended.
    pub fn new(
        nx: usize,
        ny: usize,
        values: Vec<f64>,
        pixel_um: f64,
        height_scale_um: f64,
        what: &str,
    ) -> Result<HeightField, StamError> {
        if nx < MIN_EDGE || ny < MIN_EDGE || nx > MAX_EDGE || ny > MAX_EDGE {
            return Err(StamError::new(format!(
                "height map {what} is {nx} x {ny} samples: accepted {MIN_EDGE} to {MAX_EDGE} along each edge"
            )));
        }
        debug_assert_eq!(values.len(), nx * ny);
        if let Some(at) = values.iter().position(|v| !v.is_finite()) {
            return Err(StamError::new(format!(
                "height map {what} holds {} at row {}, column {} (every height must be finite)",
                values[at],
                at / nx,
                at % nx
            )));
        }
        let mut field = HeightField {
            nx,
            ny,
            pixel_um,
            heights_um: values.into_iter().map(|v| v * height_scale_um).collect(),
        };
        field.detrend();
        Ok(field)
    }

    /// Removes the least-squares plane a + b x + c y (x, y centred, so the
    /// three are independent).
    fn detrend(&mut self) {
        let (nx, ny) = (self.nx, self.ny);
        let (cx, cy) = ((nx as f64 - 1.0) / 2.0, (ny as f64 - 1.0) / 2.0);
        let (mut sum, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (j, row) in self.heights_um.chunks(nx).enumerate() {
            let y = j as f64 - cy;
            for (i, &h) in row.iter().enumerate() {
                sum += h;
                sx += h * (i as f64 - cx);
                sy += h * y;
            }
        }
        let n = (nx * ny) as f64;
        // sum of (i - cx)^2 over a row is nx (nx^2 - 1) / 12.
        let xx = ny as f64 * nx as f64 * (nx as f64 * nx as f64 - 1.0) / 12.0;
        let yy = nx as f64 * ny as f64 * (ny as f64 * ny as f64 - 1.0) / 12.0;
        let (mean, bx, by) = (sum / n, sx / xx, sy / yy);
        for (j, row) in self.heights_um.chunks_mut(nx).enumerate() {
            let y = j as f64 - cy;
            for (i, h) in row.iter_mut().enumerate() {
                *h -= mean + bx * (i as f64 - cx) + by * y;
            }
        }
    }

    /// rms height (um) of the detrended map.
    pub fn rms_um(&self) -> f64 {
        let n = self.heights_um.len() as f64;
        (self.heights_um.iter().map(|h| h * h).sum::<f64>() / n).sqrt()
    }
}

/// A map's values as a reader gives them: (nx, ny, row-major values).
type MapValues = (usize, usize, Vec<f64>);

/// The values of the map file `path` as (nx, ny, row-major values).
pub fn read_map(path: &str) -> Result<(usize, usize, Vec<f64>), StamError> {
    let bytes = std::fs::read(path).map_err(|e| {
        StamError::new(format!(
            "parameter 'file': cannot read height map '{path}': {e}"
        ))
    })?;
    let lower = path.to_ascii_lowercase();
    let reader: fn(&[u8]) -> Result<MapValues, String> = if lower.ends_with(".npy") {
        read_npy
    } else if lower.ends_with(".csv") || lower.ends_with(".txt") {
        read_csv
    } else if lower.ends_with(".exr") {
        read_exr
    } else if lower.ends_with(".png") {
        read_png
    } else if lower.ends_with(".tif") || lower.ends_with(".tiff") {
        read_tiff
    } else {
        return Err(StamError::new(format!(
            "parameter 'file' = '{path}': accepted formats are .npy, .exr, .tif/.tiff, .png and \
             .csv (another image converts with numpy: np.save('map.npy', imageio.imread(...)))"
        )));
    };
    reader(&bytes).map_err(|e| StamError::new(format!("height map '{path}': {e}")))
}

/// A PNG image's gray values (8 or 16 bits; an alpha channel is ignored),
/// as integers: `height_scale_um` gives micrometres per unit, as profilometers
/// export 16-bit maps.
fn read_png(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    // 16-bit samples kept as they are; palettes and low bit depths expanded
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("not a readable PNG image ({e})"))?;
    let size = reader
        .output_buffer_size()
        .ok_or("the PNG image is too large")?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("not a readable PNG image ({e})"))?;
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        other => {
            return Err(format!(
                "a height map is one channel of gray, not a PNG of colour type {other:?}"
            ))
        }
    };
    let (nx, ny) = (info.width as usize, info.height as usize);
    let bytes_per = if info.bit_depth == png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    let line = info.line_size;
    let mut values = Vec::with_capacity(nx * ny);
    for row in buf[..line * ny].chunks(line) {
        for px in row[..nx * channels * bytes_per].chunks(channels * bytes_per) {
            values.push(if bytes_per == 2 {
                u16::from_be_bytes([px[0], px[1]]) as f64
            } else {
                px[0] as f64
            });
        }
    }
    Ok((nx, ny, values))
}

/// A TIFF image's first page: one channel of gray (an alpha channel is
/// ignored) in any sample type (floats as profilometers and Gwyddion write
/// them; integers scaled by `height_scale_um`), uncompressed, LZW or
/// Deflate.
fn read_tiff(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    use tiff::decoder::{Decoder, DecodingResult};
    let bad = |e: tiff::TiffError| format!("not a readable TIFF image ({e})");
    let mut decoder = Decoder::new(std::io::Cursor::new(bytes)).map_err(bad)?;
    let (nx, ny) = decoder.dimensions().map_err(bad)?;
    let channels = match decoder.colortype().map_err(bad)? {
        tiff::ColorType::Gray(_) => 1,
        tiff::ColorType::GrayA(_) => 2,
        other => {
            return Err(format!(
                "a height map is one channel of gray, not a TIFF of colour type {other:?}"
            ))
        }
    };
    let all: Vec<f64> = match decoder.read_image().map_err(bad)? {
        DecodingResult::U8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::U64(v) => v.into_iter().map(|x| x as f64).collect(),
        DecodingResult::F16(v) => v.into_iter().map(|x| x.to_f64()).collect(),
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F64(v) => v,
        DecodingResult::I8(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I16(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::I64(v) => v.into_iter().map(|x| x as f64).collect(),
    };
    let (nx, ny) = (nx as usize, ny as usize);
    if all.len() != nx * ny * channels {
        return Err(format!("{} samples for {nx} x {ny} pixels", all.len()));
    }
    Ok((nx, ny, all.into_iter().step_by(channels).collect()))
}

/// A .npy file's 2-D array.
fn read_npy(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (no NumPy magic)".into());
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!(".npy version {v} is not supported")),
    };
    let header = bytes
        .get(start..start + header_len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or("truncated .npy header")?;
    let field = |key: &str| -> Option<&str> {
        let at = header.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
        Some(rest)
    };
    let descr = field("descr")
        .and_then(|r| r.strip_prefix('\''))
        .and_then(|r| r.split('\'').next())
        .ok_or("no 'descr' in the .npy header")?;
    let fortran = field("fortran_order")
        .map(|r| r.starts_with("True"))
        .ok_or("no 'fortran_order' in the .npy header")?;
    let shape: Vec<usize> = field("shape")
        .and_then(|r| r.strip_prefix('('))
        .and_then(|r| r.split(')').next())
        .ok_or("no 'shape' in the .npy header")?
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| format!("bad shape entry '{s}'")))
        .collect::<Result<_, _>>()?;
    let [ny, nx] = shape[..] else {
        return Err(format!(
            "the array has shape {shape:?}: a height map is a 2-D array (one channel)"
        ));
    };
    let (order, kind, size) = {
        let mut c = descr.chars();
        let order = c.next().ok_or("empty dtype")?;
        let kind = c.next().ok_or("empty dtype")?;
        let size: usize = c.as_str().parse().map_err(|_| format!("dtype '{descr}'"))?;
        (order, kind, size)
    };
    let big = order == '>';
    let data = &bytes[start + header_len..];
    let count = nx * ny;
    if data.len() < count * size {
        return Err(format!(
            "the data is truncated: {} bytes for {ny} x {nx} values of {size} bytes",
            data.len()
        ));
    }
    let word = |i: usize| -> [u8; 8] {
        let mut w = [0u8; 8];
        let src = &data[i * size..(i + 1) * size];
        if big {
            for (d, s) in w.iter_mut().zip(src.iter().rev()) {
                *d = *s;
            }
        } else {
            w[..size].copy_from_slice(src);
        }
        w
    };
    let decode: Box<dyn Fn(usize) -> f64> = match (kind, size) {
        ('f', 8) => Box::new(|i| f64::from_le_bytes(word(i))),
        ('f', 4) => Box::new(|i| f32::from_le_bytes(word(i)[..4].try_into().unwrap()) as f64),
        ('i', 1 | 2 | 4 | 8) => Box::new(move |i| {
            let shift = 64 - 8 * size as u32;
            ((i64::from_le_bytes(word(i)) << shift) >> shift) as f64
        }),
        ('u', 1 | 2 | 4 | 8) => Box::new(|i| u64::from_le_bytes(word(i)) as f64),
        _ => {
            return Err(format!(
                "dtype '{descr}' is not supported (floats and integers are)"
            ))
        }
    };
    let mut values = vec![0.0; count];
    for (i, v) in values.iter_mut().enumerate() {
        // Row-major (row j, column c) from the file's order.
        let (j, c) = (i / nx, i % nx);
        *v = decode(if fortran { c * ny + j } else { i });
    }
    Ok((nx, ny, values))
}

/// An OpenEXR image's first layer: its one channel, or of several the
/// luminance `Y`, else `R` (a height map saved as an RGB image), else the
/// first; rows top to bottom along y, as the file stores them.
fn read_exr(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| format!("not a readable OpenEXR image ({e})"))?;
    let layer = &image.layer_data;
    let (nx, ny) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let named = |name: &str| list.iter().find(|c| c.name.eq_case_insensitive(name));
    let channel = named("Y")
        .or_else(|| named("R"))
        .or(list.first())
        .ok_or("the image has no channel")?;
    let values: Vec<f64> = channel.sample_data.values_as_f32().map(f64::from).collect();
    if values.len() != nx * ny {
        return Err(format!("{} samples for {nx} x {ny} pixels", values.len()));
    }
    Ok((nx, ny, values))
}

/// A CSV (or whitespace-separated) table: one row of the map per line,
/// lines starting with '#' skipped.
fn read_csv(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "the file is not text".to_string())?;
    let mut values = Vec::new();
    let (mut nx, mut ny) = (0, 0);
    for (line_no, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let row: Vec<f64> = line
            .split(|c: char| c == ',' || c == ';' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| format!("line {}: '{s}' is not a number", line_no + 1))
            })
            .collect::<Result<_, _>>()?;
        if ny == 0 {
            nx = row.len();
        } else if row.len() != nx {
            return Err(format!(
                "line {} has {} values, the first row {nx}",
                line_no + 1,
                row.len()
            ));
        }
        values.extend(row);
        ny += 1;
    }
    Ok((nx, ny, values))
}
