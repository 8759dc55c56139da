//! Rigorous efficiencies tabulated for rendering: each reflected order's
//! unpolarised efficiency over (wavelength, kx, ky), where (kx, ky) is the
//! incident light's tangential wavevector over k0 (x across the grooves),
//! built once per grating on all cores and kept in an in-process cache and
//! an on-disk cache (keyed by the grating, the grid and `SOLVER_VERSION`).
//!
//! Efficiencies do not change under ky -> -ky (the grating is invariant
//! along y), so the table covers ky >= 0. Rows are (wavelength, kx) on a
//! uniform grid; one eigen-decomposition per row serves every ky
//! (`solver::Prepared`). Efficiencies have kinks (and, in p, resonances) at
//! the Rayleigh anomalies, where an order m grazes:
//! ky_m = sqrt(n1^2 - (kx + m lambda / Lam)^2). A row's ky nodes are placed
//! on these anomalies (its breakpoints, from 0 up to ky_0, the edge of the
//! incidence disc) and `nodes_per_gap` - 1 more between each two, spaced
//! as 1 - cos, dense next to the anomalies where efficiencies go as a square
//! root. A lookup interpolates along each neighbouring row at the same
//! place relative to the query's own anomalies (the fraction of the way
//! between the same two orders' breakpoints), so a kink stays a kink
//! instead of being smeared over a grid cell.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use super::layers::{Grating, Medium};
use super::solver::{prepare, Factorisation};
use crate::optics::profile::Profile;
use crate::StamError;

/// Bump when the solver's results change: it keys the on-disk cache.
pub const SOLVER_VERSION: u32 = 1;

/// The grid of a table and the solver's truncation.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSpec {
    pub lambda_min_nm: f64,
    pub lambda_max_nm: f64,
    pub n_lambda: usize,
    /// Rows over kx in [-n1, n1].
    pub n_kx: usize,
    /// ky nodes from one anomaly to the next in a row (>= 1).
    pub nodes_per_gap: usize,
    /// Fourier orders -N..N of the solver.
    pub orders: usize,
    /// Index of the incidence medium.
    pub cover_eta: f64,
}

/// One (wavelength, kx) row: efficiencies at ky nodes.
#[derive(Clone, Debug)]
struct Row {
    ky: Vec<f64>,
    /// [node][m - m_min].
    values: Vec<f32>,
}

/// Unpolarised efficiencies of orders m_min..=m_max; zero where an order
/// does not propagate.
#[derive(Clone, Debug)]
pub struct EfficiencyTable {
    pub spec: TableSpec,
    pub m_min: i64,
    pub m_max: i64,
    period_um: f64,
    /// [lambda][kx].
    rows: Vec<Row>,
    /// Seconds the build took (0 when read from the disk cache).
    pub build_seconds: f64,
}

/// The anomalies of a row up to the incidence disc's edge, ascending in ky:
/// (ky, the orders grazing there); the first is (0, []), the last
/// (ky_0, [0, ...]).
fn breakpoints(lambda_nm: f64, period_um: f64, kx: f64, n1: f64) -> Vec<(f64, Vec<i64>)> {
    let step = lambda_nm * 1e-3 / period_um;
    let reach = (2.0 * n1 / step).ceil() as i64 + 1;
    // Beyond the disc's edge ky_0 no light arrives: anomalies there do not count.
    let edge = (n1 * n1 - kx * kx).max(0.0).sqrt();
    let mut points: Vec<(f64, Vec<i64>)> = vec![(0.0, Vec::new())];
    for m in -reach..=reach {
        let k = kx + m as f64 * step;
        if k.abs() < n1 {
            let ky = (n1 * n1 - k * k).sqrt();
            if ky <= edge {
                points.push((ky, vec![m]));
            }
        }
    }
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Merge anomalies closer than 1e-9 (orders +-m at kx = 0, say).
    let mut merged: Vec<(f64, Vec<i64>)> = Vec::with_capacity(points.len());
    for (ky, ms) in points {
        match merged.last_mut() {
            Some(last) if ky - last.0 < 1e-9 => last.1.extend(ms),
            _ => merged.push((ky, ms)),
        }
    }
    merged
}

/// ky nodes of a row: `per_gap` per gap between breakpoints, 1 - cos spaced,
/// a hair inside each gap's ends (an order exactly grazing is a limit).
fn row_nodes(points: &[(f64, Vec<i64>)], per_gap: usize) -> Vec<f64> {
    let mut nodes = Vec::new();
    for pair in points.windows(2) {
        let (a, b) = (pair[0].0, pair[1].0);
        let margin = 1e-12 * (b - a);
        for l in 0..=per_gap {
            if l == 0 && !nodes.is_empty() {
                continue;
            }
            let t = 0.5 * (1.0 - (std::f64::consts::PI * l as f64 / per_gap as f64).cos());
            let y = a + (b - a) * t;
            nodes.push(y.clamp(
                a + if pair[0].1.is_empty() { 0.0 } else { margin },
                b - margin,
            ));
        }
    }
    nodes
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

    fn orders(&self) -> usize {
        (self.m_max - self.m_min + 1) as usize
    }

    fn row(&self, il: usize, ix: usize) -> &Row {
        &self.rows[il * self.spec.n_kx + ix]
    }

    /// The ky nodes of row (il, ix).
    pub fn ky_nodes(&self, il: usize, ix: usize) -> &[f64] {
        &self.row(il, ix).ky
    }

    /// Memory held by the values and nodes.
    pub fn memory_bytes(&self) -> usize {
        self.rows
            .iter()
            .map(|r| r.values.len() * 4 + r.ky.len() * 8)
            .sum()
    }

    /// Efficiency of order m at node `iy` of row (il, ix).
    pub fn at_node(&self, il: usize, ix: usize, iy: usize, m: i64) -> f64 {
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        self.row(il, ix).values[iy * self.orders() + (m - self.m_min) as usize] as f64
    }

    /// The kx at which row ix was solved (just inside the disc at its ends).
    fn row_kx(&self, ix: usize) -> f64 {
        let n1 = self.spec.cover_eta;
        self.kx(ix).clamp(-0.9995 * n1, 0.9995 * n1)
    }

    /// Order m along row (il, ix) at `ky`: linear in the nodes' parameter u
    /// (ky = a + (b - a)(1 - cos pi u) / 2 within the gap (a, b)), in which a
    /// square root at an anomaly is a straight line.
    fn along_row(&self, il: usize, ix: usize, ky: f64, k: usize) -> f64 {
        let row = self.row(il, ix);
        let n = row.ky.len();
        if n == 0 {
            return 0.0;
        }
        let orders = self.orders();
        let at = |i: usize| row.values[i * orders + k] as f64;
        let points = breakpoints(
            self.lambda_nm(il),
            self.period_um,
            self.row_kx(ix),
            self.spec.cover_eta,
        );
        let per_gap = self.spec.nodes_per_gap;
        if points.len() < 2 || (points.len() - 1) * per_gap + 1 != n {
            return at(0);
        }
        let g = points
            .partition_point(|p| p.0 <= ky)
            .clamp(1, points.len() - 1)
            - 1;
        let (a, b) = (points[g].0, points[g + 1].0);
        let t = if b > a {
            ((ky - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let x = (g as f64 + (1.0 - 2.0 * t).acos() / std::f64::consts::PI) * per_gap as f64;
        let i = (x.floor() as usize).min(n - 2);
        let w = x - i as f64;
        at(i) + w * (at(i + 1) - at(i))
    }

    /// Efficiency of order m at (lambda, kx, ky): bilinear over the four
    /// rows around (lambda, kx), each read at the query's place between its
    /// two neighbouring anomalies (see the module comment).
    pub fn efficiency(&self, lambda_nm: f64, kx: f64, ky: f64, m: i64) -> f64 {
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        let s = &self.spec;
        let n1 = s.cover_eta;
        let ky = ky.abs();
        let cell = |x: f64, min: f64, max: f64, n: usize| -> (usize, f64) {
            if n < 2 {
                return (0, 0.0);
            }
            let t = ((x - min) / (max - min) * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
            let i = (t.floor() as usize).min(n - 2);
            (i, t - i as f64)
        };
        let (il, tl) = cell(lambda_nm, s.lambda_min_nm, s.lambda_max_nm, s.n_lambda);
        let (ix, tx) = cell(kx, -n1, n1, s.n_kx);
        let step = |i: usize, n: usize| if n < 2 { 0 } else { (i + 1).min(n - 1) };
        // The query's two neighbouring anomalies and its place between them.
        let here = breakpoints(lambda_nm, self.period_um, kx, n1);
        let j = here
            .partition_point(|p| p.0 <= ky)
            .clamp(1, here.len().max(2) - 1);
        let (lo, hi) = (&here[j - 1], &here[j.min(here.len() - 1)]);
        let t = if hi.0 > lo.0 {
            ((ky - lo.0) / (hi.0 - lo.0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let k = (m - self.m_min) as usize;
        let mut sum = 0.0;
        for (jl, wl) in [(il, 1.0 - tl), (step(il, s.n_lambda), tl)] {
            for (jx, wx) in [(ix, 1.0 - tx), (step(ix, s.n_kx), tx)] {
                let w = wl * wx;
                if w == 0.0 {
                    continue;
                }
                let there = breakpoints(self.lambda_nm(jl), self.period_um, self.row_kx(jx), n1);
                let find = |labels: &Vec<i64>| -> Option<f64> {
                    if labels.is_empty() {
                        return Some(0.0);
                    }
                    there
                        .iter()
                        .find(|p| p.1.iter().any(|l| labels.contains(l)))
                        .map(|p| p.0)
                };
                // The same two anomalies in that row, else the same ky.
                let ky_there = match (find(&lo.1), find(&hi.1)) {
                    (Some(a), Some(b)) if b > a => a + t * (b - a),
                    _ => ky,
                };
                sum += w * self.along_row(jl, jx, ky_there, k);
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
    if spec.n_lambda < 1 || spec.n_kx < 2 || spec.nodes_per_gap < 1 {
        return Err(StamError::new(
            "rigorous table: at least 1 wavelength, 2 kx rows and 1 node per gap",
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
        period_um: grating.period_um,
        rows: Vec::new(),
        build_seconds: 0.0,
    };
    let rows: Vec<(usize, usize)> = (0..spec.n_lambda)
        .flat_map(|il| (0..spec.n_kx).map(move |ix| (il, ix)))
        .collect();
    let start = Instant::now();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let last_report = Mutex::new(0.0f64);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Row)>> = Mutex::new(Vec::with_capacity(rows.len()));
    let first_error: Mutex<Option<StamError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let r = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if r >= rows.len() || first_error.lock().unwrap().is_some() {
                    break;
                }
                let (il, ix) = rows[r];
                match solve_row(grating, &table, il, ix) {
                    Ok(row) => results.lock().unwrap().push((r, row)),
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
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|(r, _)| *r);
    table.rows = results.into_iter().map(|(_, row)| row).collect();
    table.build_seconds = start.elapsed().as_secs_f64();
    Ok(table)
}

/// One (wavelength, kx) row: every ky node up to the incidence disc's edge
/// (a kx at or beyond the edge is read just inside it).
fn solve_row(
    grating: &Grating,
    table: &EfficiencyTable,
    il: usize,
    ix: usize,
) -> Result<Row, StamError> {
    let spec = &table.spec;
    let n1 = spec.cover_eta;
    let lambda = table.lambda_nm(il);
    let kx = table.kx(ix).clamp(-0.9995 * n1, 0.9995 * n1);
    let points = breakpoints(lambda, grating.period_um, kx, n1);
    let ky = row_nodes(&points, spec.nodes_per_gap);
    let orders = table.orders();
    let mut values = vec![0.0f32; ky.len() * orders];
    let prepared = prepare(
        &grating.stack(lambda, n1),
        lambda,
        kx,
        spec.orders,
        Factorisation::Li,
    )?;
    for (iy, &y) in ky.iter().enumerate() {
        let d = prepared.solve(y);
        for o in &d.reflected {
            if o.m >= table.m_min && o.m <= table.m_max {
                values[iy * orders + (o.m - table.m_min) as usize] = o.unpolarised() as f32;
            }
        }
    }
    Ok(Row { ky, values })
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
    let mut bytes = Vec::new();
    bytes.extend_from_slice(&(key.len() as u64).to_le_bytes());
    bytes.extend_from_slice(key.as_bytes());
    bytes.extend_from_slice(&table.m_min.to_le_bytes());
    bytes.extend_from_slice(&table.m_max.to_le_bytes());
    bytes.extend_from_slice(&table.period_um.to_le_bytes());
    bytes.extend_from_slice(&(table.rows.len() as u64).to_le_bytes());
    for row in &table.rows {
        bytes.extend_from_slice(&(row.ky.len() as u64).to_le_bytes());
        for y in &row.ky {
            bytes.extend_from_slice(&y.to_le_bytes());
        }
        for v in &row.values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
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
    let period_um = f64::from_le_bytes(take(8)?.try_into().ok()?);
    let n_rows = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let orders = usize::try_from(m_max - m_min + 1).ok()?;
    if n_rows != spec.n_lambda * spec.n_kx {
        return None;
    }
    let mut rows = Vec::with_capacity(n_rows);
    for _ in 0..n_rows {
        let n = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
        let ky = take(8 * n)?
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        let values = take(4 * n * orders)?
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        rows.push(Row { ky, values });
    }
    Some(EfficiencyTable {
        spec: spec.clone(),
        m_min,
        m_max,
        period_um,
        rows,
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
