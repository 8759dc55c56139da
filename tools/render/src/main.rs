//! stam-render: the Rust-only reference renderer of the project.
//!
//! Computes, without Monte Carlo, the direct-lighting image of a flat
//! diffraction sample lit by a point light and seen by a pinhole camera:
//! per pixel, the average over an n x n grid of sub-pixel positions (the
//! centres of the strata of a box-filtered pixel) of
//!
//! ```text
//!     L = f(w_view, w_light) cos(theta_light) I / r^2
//! ```
//!
//! with f from the core (`stam::Brdf`), in the same camera, light and
//! shading frames as the Mitsuba scene that `scripts/compare.py` builds
//! from the same configuration:
//! - sample: Mitsuba's `rectangle` scaled by `half_size` in x and y, at z = 0,
//!   normal +z; uv = ((x / s + 1) / 2, (y / s + 1) / 2); shading tangent +x;
//! - camera: Mitsuba's `perspective` sensor, `fov` along x, `look_at(origin,
//!   target, up)`; film sample (sx, sy) in [0, 1]^2, (0, 0) = top left;
//! - light: Mitsuba's `point` emitter of intensity I at `light_pos`;
//! - frames: the plugin's `twist` (degrees, about the normal) and
//!   `tracks` = "linear" (periodic direction = tangent) or "concentric"
//!   (periodic direction radial about `center_uv`, grooves along circles).
//!   The core's wi is the direction to the camera (Mitsuba's si.wi) and its
//!   wo the direction to the light, as in the plugin.
//!
//! Usage: `stam-render CONFIG.json OUT.npy`. The output is a float32 NPY
//! array (height, width, C + 1): C colour channels then the fraction of the
//! sub-pixel positions that hit the sample (1 inside, 0 outside, between on
//! its edges). Channels by `mode`:
//! - `"rgb"`: the core's linear-sRGB BRDF (`Brdf::eval_rgb`, what Mitsuba's
//!   RGB variants use), C = 3;
//! - `{"cie_step_nm": h}`: the spectral BRDF integrated against D65 and the
//!   CIE 1931 matching functions on an h-nm grid (`Brdf::eval_rgb_reference`:
//!   what a spectral render under a D65 light converges to), C = 3;
//! - `{"wavelengths_nm": [l1, ...]}`: the spectral BRDF at those wavelengths
//!   (`Brdf::eval_spectral`), one channel each.
//!
//! Optional config key `threads` (default: all cores).

use std::f64::consts::PI;
use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::DVec3;
use serde_json::Value;
use stam::Brdf;

enum Mode {
    Rgb,
    Cie(f64),
    Wavelengths(Vec<f64>),
}

impl Mode {
    fn channels(&self) -> usize {
        match self {
            Mode::Rgb | Mode::Cie(_) => 3,
            Mode::Wavelengths(w) => w.len(),
        }
    }
}

enum Tracks {
    Linear,
    Concentric { cu: f64, cv: f64 },
}

struct Config {
    width: usize,
    height: usize,
    fov_x_deg: f64,
    origin: DVec3,
    target: DVec3,
    up: DVec3,
    half_size: f64,
    light_pos: DVec3,
    intensity: f64,
    twist_deg: f64,
    tracks: Tracks,
    subpixels: usize,
    mode: Mode,
    threads: usize,
}

fn fail(msg: impl AsRef<str>) -> ! {
    eprintln!("stam-render: {}", msg.as_ref());
    std::process::exit(2)
}

fn num(v: &Value, key: &str) -> f64 {
    v.get(key)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| fail(format!("config: \"{key}\" must be a number")))
}

fn num_or(v: &Value, key: &str, default: f64) -> f64 {
    match v.get(key) {
        None => default,
        Some(_) => num(v, key),
    }
}

fn vec3(v: &Value, key: &str) -> DVec3 {
    let a = v
        .get(key)
        .and_then(Value::as_array)
        .filter(|a| a.len() == 3)
        .unwrap_or_else(|| fail(format!("config: \"{key}\" must be [x, y, z]")));
    let c = |i: usize| {
        a[i].as_f64()
            .unwrap_or_else(|| fail(format!("config: \"{key}\" must hold numbers")))
    };
    DVec3::new(c(0), c(1), c(2))
}

fn parse_config(v: &Value) -> (Config, String) {
    let material = v
        .get("material")
        .filter(|m| m.is_object())
        .unwrap_or_else(|| fail("config: \"material\" must be the core's JSON object"))
        .to_string();
    let tracks = match v.get("tracks").and_then(Value::as_str).unwrap_or("linear") {
        "linear" => Tracks::Linear,
        "concentric" => {
            let (cu, cv) = match v.get("center_uv").and_then(Value::as_array) {
                Some(a) if a.len() == 2 => {
                    (a[0].as_f64().unwrap_or(0.5), a[1].as_f64().unwrap_or(0.5))
                }
                _ => (0.5, 0.5),
            };
            Tracks::Concentric { cu, cv }
        }
        t => fail(format!("config: tracks = \"{t}\": linear or concentric")),
    };
    let mode = match v.get("mode") {
        None => Mode::Rgb,
        Some(Value::String(s)) if s == "rgb" => Mode::Rgb,
        Some(m) if m.get("cie_step_nm").is_some() => Mode::Cie(num(m, "cie_step_nm")),
        Some(m) if m.get("wavelengths_nm").is_some() => Mode::Wavelengths(
            m["wavelengths_nm"]
                .as_array()
                .unwrap_or_else(|| fail("config: wavelengths_nm must be a list"))
                .iter()
                .map(|x| x.as_f64().unwrap_or_else(|| fail("config: bad wavelength")))
                .collect(),
        ),
        Some(m) => fail(format!("config: unknown mode {m}")),
    };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cfg = Config {
        width: num(v, "width") as usize,
        height: num(v, "height") as usize,
        fov_x_deg: num(v, "fov_x_deg"),
        origin: vec3(v, "origin"),
        target: vec3(v, "target"),
        up: vec3(v, "up"),
        half_size: num(v, "half_size"),
        light_pos: vec3(v, "light_pos"),
        intensity: num(v, "intensity"),
        twist_deg: num_or(v, "twist_deg", 0.0),
        tracks,
        subpixels: num_or(v, "subpixels", 4.0) as usize,
        mode,
        threads: num_or(v, "threads", threads as f64).max(1.0) as usize,
    };
    if cfg.width == 0 || cfg.height == 0 || cfg.subpixels == 0 || cfg.mode.channels() == 0 {
        fail("config: width, height, subpixels and channels must be positive");
    }
    (cfg, material)
}

/// Mitsuba's look_at camera: columns (left, up, dir).
struct Camera {
    origin: DVec3,
    left: DVec3,
    up: DVec3,
    dir: DVec3,
    tan_x: f64,
    tan_y: f64,
}

impl Camera {
    fn new(c: &Config) -> Camera {
        let dir = (c.target - c.origin).normalize();
        let left = c.up.normalize().cross(dir).normalize();
        let up = dir.cross(left);
        let tan_x = (0.5 * c.fov_x_deg * PI / 180.0).tan();
        let aspect = c.width as f64 / c.height as f64;
        Camera {
            origin: c.origin,
            left,
            up,
            dir,
            tan_x,
            tan_y: tan_x / aspect,
        }
    }

    /// Ray direction through film position (sx, sy) in [0, 1]^2.
    fn ray(&self, sx: f64, sy: f64) -> DVec3 {
        let x = (1.0 - 2.0 * sx) * self.tan_x;
        let y = (1.0 - 2.0 * sy) * self.tan_y;
        (self.left * x + self.up * y + self.dir).normalize()
    }
}

struct Renderer {
    cfg: Config,
    cam: Camera,
    brdf: Brdf,
    cos_twist: f64,
    sin_twist: f64,
}

impl Renderer {
    /// Rotation (c, s) taking the local frame to the core's: core x = (c, s, 0).
    fn frame(&self, p: DVec3) -> (f64, f64) {
        let (ct, st) = (self.cos_twist, self.sin_twist);
        match self.cfg.tracks {
            Tracks::Linear => (ct, st),
            Tracks::Concentric { cu, cv } => {
                let s = self.cfg.half_size;
                let du = (p.x / s + 1.0) * 0.5 - cu;
                let dv = (p.y / s + 1.0) * 0.5 - cv;
                // Groove direction (-dv, du) (dp_du, dp_dv are +x, +y); the
                // periodic direction is radial.
                let len = (du * du + dv * dv).sqrt();
                let (c0, s0) = if len > 1e-20 {
                    (du / len, dv / len)
                } else {
                    (1.0, 0.0)
                };
                (c0 * ct - s0 * st, s0 * ct + c0 * st)
            }
        }
    }

    /// Radiance towards the camera along film position (sx, sy); None: miss.
    fn radiance(&self, sx: f64, sy: f64, out: &mut [f64]) -> bool {
        let d = self.cam.ray(sx, sy);
        let o = self.cam.origin;
        if d.z.abs() < 1e-300 {
            return false;
        }
        let t = -o.z / d.z;
        if t <= 0.0 {
            return false;
        }
        let p = o + d * t;
        let s = self.cfg.half_size;
        if p.x.abs() > s || p.y.abs() > s {
            return false;
        }
        out.iter_mut().for_each(|x| *x = 0.0);
        let w_view = -d;
        let to_light = self.cfg.light_pos - p;
        let r2 = to_light.length_squared();
        let w_light = to_light / r2.sqrt();
        if w_view.z <= 0.0 || w_light.z <= 0.0 {
            return true; // hit, but unlit or seen from below
        }
        let (c, sn) = self.frame(p);
        let to_core = |w: DVec3| DVec3::new(c * w.x + sn * w.y, -sn * w.x + c * w.y, w.z);
        let (wi, wo) = (to_core(w_view), to_core(w_light));
        let scale = w_light.z * self.cfg.intensity / r2;
        match &self.cfg.mode {
            Mode::Rgb => {
                let f = self.brdf.eval_rgb(wi, wo);
                for k in 0..3 {
                    out[k] = f[k] * scale;
                }
            }
            Mode::Cie(step) => {
                let f = self.brdf.eval_rgb_reference(wi, wo, *step);
                for k in 0..3 {
                    out[k] = f[k] * scale;
                }
            }
            Mode::Wavelengths(ls) => {
                for (k, &l) in ls.iter().enumerate() {
                    out[k] = self.brdf.eval_spectral(wi, wo, l) * scale;
                }
            }
        }
        true
    }

    fn render_row(&self, j: usize, row: &mut [f32]) {
        let (w, h, n) = (self.cfg.width, self.cfg.height, self.cfg.subpixels);
        let nc = self.cfg.mode.channels();
        let mut acc = vec![0.0f64; nc];
        let mut l = vec![0.0f64; nc];
        for i in 0..w {
            acc.iter_mut().for_each(|x| *x = 0.0);
            let mut hits = 0usize;
            for b in 0..n {
                for a in 0..n {
                    let sx = (i as f64 + (a as f64 + 0.5) / n as f64) / w as f64;
                    let sy = (j as f64 + (b as f64 + 0.5) / n as f64) / h as f64;
                    if self.radiance(sx, sy, &mut l) {
                        hits += 1;
                        for k in 0..nc {
                            acc[k] += l[k];
                        }
                    }
                }
            }
            let inv = 1.0 / (n * n) as f64;
            let px = &mut row[i * (nc + 1)..(i + 1) * (nc + 1)];
            for k in 0..nc {
                px[k] = (acc[k] * inv) as f32;
            }
            px[nc] = (hits as f64 * inv) as f32;
        }
    }
}

fn write_npy(path: &str, shape: [usize; 3], data: &[f32]) -> std::io::Result<()> {
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        shape[0], shape[1], shape[2]
    );
    // magic (6) + version (2) + header length (2) + header + '\n': multiple of 64
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    f.write_all(b"\x93NUMPY\x01\x00")?;
    f.write_all(&(header.len() as u16).to_le_bytes())?;
    f.write_all(header.as_bytes())?;
    for x in data {
        f.write_all(&x.to_le_bytes())?;
    }
    f.flush()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        fail("usage: stam-render CONFIG.json OUT.npy");
    }
    let text = std::fs::read_to_string(&args[1])
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", args[1])));
    let v: Value =
        serde_json::from_str(&text).unwrap_or_else(|e| fail(format!("{}: {e}", args[1])));
    let (cfg, material) = parse_config(&v);
    let brdf = Brdf::from_json(&material).unwrap_or_else(|e| fail(format!("material: {e}")));
    let t = cfg.twist_deg * PI / 180.0;
    let r = Renderer {
        cam: Camera::new(&cfg),
        cos_twist: t.cos(),
        sin_twist: t.sin(),
        brdf,
        cfg,
    };

    let (w, h) = (r.cfg.width, r.cfg.height);
    let stride = w * (r.cfg.mode.channels() + 1);
    let mut image = vec![0.0f32; h * stride];
    let next = AtomicUsize::new(0);
    {
        // Rows handed out dynamically; each worker owns disjoint rows.
        let rows: Vec<std::sync::Mutex<&mut [f32]>> = image
            .chunks_mut(stride)
            .map(std::sync::Mutex::new)
            .collect();
        std::thread::scope(|s| {
            for _ in 0..r.cfg.threads.min(h) {
                s.spawn(|| loop {
                    let j = next.fetch_add(1, Ordering::Relaxed);
                    if j >= h {
                        break;
                    }
                    let mut row = rows[j].lock().unwrap();
                    r.render_row(j, &mut row);
                });
            }
        });
    }
    write_npy(&args[2], [h, w, r.cfg.mode.channels() + 1], &image)
        .unwrap_or_else(|e| fail(format!("cannot write {}: {e}", args[2])));
}
