//! Rigorous efficiencies tabulated for rendering: each reflected order's
//! unpolarised efficiency over (wavelength, kx, ky), where (kx, ky) is the
//! incident light's tangential wavevector over k0 (x across the grooves),
//! built once per grating on all cores and kept in an in-process cache and
//! an on-disk cache (keyed by the grating, the grid and `SOLVER_VERSION`).
//!
//! Efficiencies do not change under ky -> -ky (the grating is invariant
//! along y), so the table covers ky >= 0. One eigen-decomposition per
//! (wavelength, kx) serves every ky (`solver::Prepared`). Nodes outside the
//! disc kx^2 + ky^2 < n1^2 (no incident direction reaches them) hold the
//! values at the disc's edge along the same azimuth, so that interpolation
//! near grazing incidence reads physical values.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use super::layers::{Grating, Medium};
use super::solver::{prepare, Factorisation};
use crate::models::periodic::Profile;
use crate::StamError;

/// Bump when the solver's results change: it keys the on-disk cache.
pub const SOLVER_VERSION: u32 = 1;

/// The grid of a table and the solver's truncation.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSpec {
    pub lambda_min_nm: f64,
    pub lambda_max_nm: f64,
    pub n_lambda: usize,
    /// Nodes over kx in [-n1, n1].
    pub n_kx: usize,
    /// Nodes over ky in [0, n1].
    pub n_ky: usize,
    /// Fourier orders -N..N of the solver.
    pub orders: usize,
    /// Index of the incidence medium.
    pub cover_eta: f64,
}

/// Unpolarised efficiencies of orders m_min..=m_max on the grid; zero where
/// an order does not propagate.
#[derive(Clone, Debug)]
pub struct EfficiencyTable {
    pub spec: TableSpec,
    pub m_min: i64,
    pub m_max: i64,
    /// [lambda][kx][ky][m - m_min].
    values: Vec<f32>,
    /// Seconds the build took (0 when read from the disk cache).
    pub build_seconds: f64,
}

fn node(min: f64, max: f64, n: usize, i: usize) -> f64 {
    if n < 2 {
        min
    } else {
        min + (max - min) * i as f64 / (n - 1) as f64
    }
}

impl EfficiencyTable {
    pub fn lambda_nm(&self, i: usize) -> f64 {
        let s = &self.spec;
        node(s.lambda_min_nm, s.lambda_max_nm, s.n_lambda, i)
    }

    pub fn kx(&self, i: usize) -> f64 {
        node(-self.spec.cover_eta, self.spec.cover_eta, self.spec.n_kx, i)
    }

    pub fn ky(&self, i: usize) -> f64 {
        node(0.0, self.spec.cover_eta, self.spec.n_ky, i)
    }

    fn orders(&self) -> usize {
        (self.m_max - self.m_min + 1) as usize
    }

    fn index(&self, il: usize, ix: usize, iy: usize) -> usize {
        ((il * self.spec.n_kx + ix) * self.spec.n_ky + iy) * self.orders()
    }

    /// Memory held by the values.
    pub fn memory_bytes(&self) -> usize {
        self.values.len() * 4
    }

    /// Efficiency of order m at a node.
    pub fn at_node(&self, il: usize, ix: usize, iy: usize, m: i64) -> f64 {
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        self.values[self.index(il, ix, iy) + (m - self.m_min) as usize] as f64
    }

    /// Efficiency of order m at (lambda, kx, ky), trilinear between nodes
    /// (clamped to the grid).
    pub fn efficiency(&self, lambda_nm: f64, kx: f64, ky: f64, m: i64) -> f64 {
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        let s = &self.spec;
        let cell = |x: f64, min: f64, max: f64, n: usize| -> (usize, f64) {
            if n < 2 {
                return (0, 0.0);
            }
            let t = ((x - min) / (max - min) * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
            let i = (t.floor() as usize).min(n - 2);
            (i, t - i as f64)
        };
        let (il, tl) = cell(lambda_nm, s.lambda_min_nm, s.lambda_max_nm, s.n_lambda);
        let (ix, tx) = cell(kx, -s.cover_eta, s.cover_eta, s.n_kx);
        let (iy, ty) = cell(ky.abs(), 0.0, s.cover_eta, s.n_ky);
        let step = |i: usize, n: usize| if n < 2 { 0 } else { (i + 1).min(n - 1) };
        let k = (m - self.m_min) as usize;
        let mut sum = 0.0;
        for (jl, wl) in [(il, 1.0 - tl), (step(il, s.n_lambda), tl)] {
            for (jx, wx) in [(ix, 1.0 - tx), (step(ix, s.n_kx), tx)] {
                for (jy, wy) in [(iy, 1.0 - ty), (step(iy, s.n_ky), ty)] {
                    let w = wl * wx * wy;
                    if w != 0.0 {
                        sum += w * self.values[self.index(jl, jx, jy) + k] as f64;
                    }
                }
            }
        }
        sum
    }
}

/// Text that identifies a table: the grating, the grid, the solver.
pub fn table_key(grating: &Grating, spec: &TableSpec) -> String {
    let profile = match &grating.profile {
        Profile::Rect {
            height_um,
            width_um,
        } => format!("rect h={height_um:e} w={width_um:e}"),
        Profile::Sine { height_um } => format!("sine h={height_um:e}"),
        Profile::Tabulated { heights_um } => format!("tabulated h={heights_um:?}"),
    };
    let metal = match grating.metal {
        Medium::Metal(t) => t.name.to_string(),
        Medium::Index { eta, k } => format!("{eta:e}+{k:e}i"),
    };
    format!(
        "stam rigorous v{SOLVER_VERSION}; period={:e} {profile} slices={} metal={metal}; {spec:?}",
        grating.period_um, grating.slices
    )
}

/// Build a table (all cores), printing progress to stderr when it takes
/// more than a second.
pub fn build(grating: &Grating, spec: &TableSpec) -> Result<EfficiencyTable, StamError> {
    if spec.n_lambda < 1 || spec.n_kx < 2 || spec.n_ky < 2 {
        return Err(StamError::new(
            "rigorous table: at least 1 wavelength, 2 kx and 2 ky nodes",
        ));
    }
    if !(spec.lambda_min_nm > 0.0 && spec.lambda_max_nm >= spec.lambda_min_nm) {
        return Err(StamError::new(format!(
            "rigorous table: wavelengths {}..{} nm",
            spec.lambda_min_nm, spec.lambda_max_nm
        )));
    }
    let n1 = spec.cover_eta;
    // Orders that can propagate anywhere on the grid: |kx + m lambda / Lam| < n1.
    let m_reach = (2.0 * n1 * grating.period_um / (spec.lambda_min_nm * 1e-3)).ceil() as i64;
    let mut table = EfficiencyTable {
        spec: spec.clone(),
        m_min: -m_reach,
        m_max: m_reach,
        values: Vec::new(),
        build_seconds: 0.0,
    };
    let per_row = spec.n_ky * table.orders();
    table.values = vec![0.0; spec.n_lambda * spec.n_kx * per_row];
    let rows: Vec<(usize, usize)> = (0..spec.n_lambda)
        .flat_map(|il| (0..spec.n_kx).map(move |ix| (il, ix)))
        .collect();
    let start = Instant::now();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let last_report = Mutex::new(0.0f64);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Vec<f32>)>> = Mutex::new(Vec::with_capacity(rows.len()));
    let first_error: Mutex<Option<StamError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let r = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if r >= rows.len() || first_error.lock().unwrap().is_some() {
                    break;
                }
                let (il, ix) = rows[r];
                match row(grating, &table, il, ix) {
                    Ok(values) => results.lock().unwrap().push((r, values)),
                    Err(e) => {
                        *first_error.lock().unwrap() = Some(e);
                        break;
                    }
                }
                let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                let elapsed = start.elapsed().as_secs_f64();
                let mut last = last_report.lock().unwrap();
                if elapsed > 1.0 && (elapsed - *last > 2.0 || finished == rows.len()) {
                    *last = elapsed;
                    eprintln!(
                        "stam: rigorous grating efficiencies: {:.0}% ({elapsed:.0} s)",
                        100.0 * finished as f64 / rows.len() as f64
                    );
                }
            });
        }
    });
    if let Some(e) = first_error.into_inner().unwrap() {
        return Err(e);
    }
    for (r, values) in results.into_inner().unwrap() {
        table.values[r * per_row..(r + 1) * per_row].copy_from_slice(&values);
    }
    table.build_seconds = start.elapsed().as_secs_f64();
    Ok(table)
}

/// One (wavelength, kx) row of the table: every ky node.
fn row(
    grating: &Grating,
    table: &EfficiencyTable,
    il: usize,
    ix: usize,
) -> Result<Vec<f32>, StamError> {
    let spec = &table.spec;
    let n1 = spec.cover_eta;
    let lambda = table.lambda_nm(il);
    let stack = grating.stack(lambda, n1);
    let edge = 0.9995 * n1;
    let kx = table.kx(ix);
    let orders = table.orders();
    let mut out = vec![0.0f32; spec.n_ky * orders];
    // Nodes beyond the disc's edge take the edge's values along their azimuth:
    // group them by the kx they are moved to.
    let mut prepared: Option<(f64, super::solver::Prepared)> = None;
    for iy in 0..spec.n_ky {
        let ky = table.ky(iy);
        let r = (kx * kx + ky * ky).sqrt();
        let (kx_at, ky_at) = if r > edge {
            (kx * edge / r, ky * edge / r)
        } else {
            (kx, ky)
        };
        let reuse = matches!(&prepared, Some((k, _)) if *k == kx_at);
        if !reuse {
            prepared = Some((
                kx_at,
                prepare(&stack, lambda, kx_at, spec.orders, Factorisation::Li)?,
            ));
        }
        let d = prepared.as_ref().expect("prepared above").1.solve(ky_at);
        for o in &d.reflected {
            if o.m >= table.m_min && o.m <= table.m_max {
                out[iy * orders + (o.m - table.m_min) as usize] = o.unpolarised() as f32;
            }
        }
    }
    Ok(out)
}

/// Where tables are kept between processes: $STAM_CACHE_DIR, else
/// $XDG_CACHE_HOME/stam-diffraction, else ~/.cache/stam-diffraction. None
/// when none can be found (the table is then built in every process).
pub fn cache_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("STAM_CACHE_DIR") {
        return Some(PathBuf::from(dir));
    }
    if let Some(dir) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(dir).join("stam-diffraction"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("stam-diffraction"))
}

/// FNV-1a, for file names (the key itself is checked on reading).
fn hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf29ce484222325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100000001b3)
    })
}

fn cache_path(key: &str) -> Option<PathBuf> {
    cache_dir().map(|d| d.join(format!("rigorous-{:016x}.bin", hash(key))))
}

fn write_cache(key: &str, table: &EfficiencyTable) -> std::io::Result<()> {
    let Some(path) = cache_path(key) else {
        return Ok(());
    };
    std::fs::create_dir_all(path.parent().expect("a file in the cache directory"))?;
    let mut bytes = Vec::with_capacity(table.values.len() * 4 + key.len() + 32);
    bytes.extend_from_slice(&(key.len() as u64).to_le_bytes());
    bytes.extend_from_slice(key.as_bytes());
    bytes.extend_from_slice(&table.m_min.to_le_bytes());
    bytes.extend_from_slice(&table.m_max.to_le_bytes());
    bytes.extend_from_slice(&(table.values.len() as u64).to_le_bytes());
    for v in &table.values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    // Write then rename: a reader never sees half a file.
    let partial = path.with_extension(format!("{}.partial", std::process::id()));
    std::fs::File::create(&partial)?.write_all(&bytes)?;
    std::fs::rename(&partial, &path)
}

/// The table stored on disk under `key`, if any (and if it is whole).
pub fn table_from_disk(key: &str, spec: &TableSpec) -> Option<EfficiencyTable> {
    let mut bytes = Vec::new();
    std::fs::File::open(cache_path(key)?)
        .ok()?
        .read_to_end(&mut bytes)
        .ok()?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = bytes.get(at..at + n)?;
        at += n;
        Some(s)
    };
    let key_len = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    if take(key_len)? != key.as_bytes() {
        return None;
    }
    let m_min = i64::from_le_bytes(take(8)?.try_into().ok()?);
    let m_max = i64::from_le_bytes(take(8)?.try_into().ok()?);
    let n = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let expected = spec.n_lambda * spec.n_kx * spec.n_ky * (m_max - m_min + 1).max(0) as usize;
    if n != expected {
        return None;
    }
    let raw = take(4 * n)?;
    let values = raw
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    Some(EfficiencyTable {
        spec: spec.clone(),
        m_min,
        m_max,
        values,
        build_seconds: 0.0,
    })
}

type Cache = Mutex<HashMap<String, Arc<EfficiencyTable>>>;

fn memory_cache() -> &'static Cache {
    static CACHE: OnceLock<Cache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The table of `grating` on `spec`: from this process's cache, else the
/// disk cache, else built (and then stored in both).
pub fn table(grating: &Grating, spec: &TableSpec) -> Result<Arc<EfficiencyTable>, StamError> {
    let key = table_key(grating, spec);
    if let Some(t) = memory_cache().lock().unwrap().get(&key) {
        return Ok(t.clone());
    }
    let table = match table_from_disk(&key, spec) {
        Some(t) => t,
        None => {
            let t = build(grating, spec)?;
            if let Err(e) = write_cache(&key, &t) {
                eprintln!("stam: could not keep the rigorous table on disk ({e}); it will be built again next time");
            }
            t
        }
    };
    let table = Arc::new(table);
    memory_cache().lock().unwrap().insert(key, table.clone());
    Ok(table)
}
