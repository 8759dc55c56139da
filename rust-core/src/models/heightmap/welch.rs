//! The tables of a height map: Stam's general result evaluated on the map
//! itself (docs/physics.md, "The general result"; docs/heightmap.md).
//!
//! With kappa = k |w| (the phase per micrometre of height) and the
//! tangential frequency nu = k (u, v) / (2 pi) = (u, v) / lambda:
//!
//! ```text
//! <|P(nu)|^2> / A = |chi(kappa)|^2 delta(nu) + S(kappa, nu),
//! chi(kappa) = mean of exp(i kappa h)          (the coherent lobe),
//! S = the power spectrum of exp(i kappa h) - chi,
//! K = k^2 / (4 pi^2 w^2) S = k^4 T / (4 pi^2),  T = S / kappa^2.
//! ```
//!
//! T has the finite limit PSD(h) as kappa -> 0 (first-order perturbation)
//! and falls as kappa^-4 where the surface is optically rough; the table
//! holds T (1 + kappa / kappa_0)^4, which varies slowly in both regimes,
//! on nodes uniform in s = ln(1 + kappa / kappa_0), kappa_0 = 1 / (4 sigma)
//! (the rough regime starts near kappa sigma ~ 1). No series in kappa h:
//! each node is the FFT of exp(i kappa h) itself, so any height works. The
//! tables know no wavelength: kappa and nu are lengths' inverses.
//!
//! One map is one realisation: S is its Welch estimate (Hann tiles of
//! `tile` samples overlapping by half, periodograms averaged), whose
//! frequency resolution 1 / (tile pixel) and noise (one over the square
//! root of the tile count) docs/heightmap.md measures against known
//! spectra.

use super::map::HeightField;
use crate::progress::Progress;
use crate::sampling::AliasTable;
use crate::spectrum::{wavenumber_per_um, LAMBDA_MIN_NM};
use num_complex::Complex;
use rustfft::FftPlanner;

/// Node spacing in s = ln(1 + kappa / kappa_0): T (1 + kappa / kappa_0)^4
/// changes by a few percent between nodes where the lobe reshapes fastest.
const NODE_STEP: f64 = 0.08;
const MIN_NODES: usize = 8;
const MAX_NODES: usize = 64;
/// A program indexes nodes x tile^2 values in f32: exact below 2^24.
const MAX_TABLE_VALUES: usize = 1 << 24;
/// Entries of the |chi|^2 table over s.
pub(super) const CHI_NODES: usize = 2048;
/// Bins of the height histogram chi is summed over: the phase error of a
/// bin, kappa (range / bins) / 2, stays below 1e-3 rad for maps up to
/// 1 um from lowest to highest point.
const HISTOGRAM_BINS: usize = 1 << 15;
/// Correlation lengths per tile edge by default: the lobe's centre is low
/// by 4-8% at 10-20 correlation lengths against known spectra
/// (docs/heightmap.md).
const TILE_CORRELATION_LENGTHS: f64 = 20.0;
const DEFAULT_TILE_RANGE: (usize, usize) = (32, 256);

/// What the model reads: T on (kappa node, nu) and |chi|^2 over s.
#[derive(Debug)]
pub struct SpectrumTable {
    /// Tile edge in samples; the frequency grid is nu_j = (j - tile / 2)
    /// / (tile pixel), j in 0..tile along each axis.
    pub tile: usize,
    /// tile * pixel_um: nu's index is nu * tile_um + tile / 2.
    pub tile_um: f64,
    pub kappa0: f64,
    /// s of the last node and of the |chi|^2 table's last entry.
    pub s_max: f64,
    pub nodes: usize,
    /// [node][iy][ix]: T (1 + kappa / kappa_0)^4 in um^4.
    pub values: Vec<f32>,
    /// [node][cell][keep, alias]: each node's values as an alias table
    /// (`AliasTable::interleaved`), which the sampling lobe draws cells
    /// from.
    pub alias: Vec<f32>,
    /// Per node: the sum of its values (a cell's probability is its value
    /// over the sum: the drawn law to f32 rounding of the keep values).
    pub totals: Vec<f64>,
    /// |chi(kappa)|^2 at s = i s_max / (CHI_NODES - 1).
    pub chi2: Vec<f32>,
    /// rms height and correlation length (1/e of the autocorrelation) of
    /// the map, um.
    pub sigma_um: f64,
    pub correlation_um: f64,
}

impl SpectrumTable {
    pub fn build(field: &HeightField, tile: Option<usize>) -> SpectrumTable {
        let sigma_um = field.rms_um();
        let correlation_um = correlation_length_um(field);
        let tile = tile.unwrap_or_else(|| default_tile(field, correlation_um));
        // The roughness scale; a flat map (sigma 0) gets a finite one.
        let kappa0 = 1.0 / (4.0 * sigma_um.max(1e-6));
        let kappa_max = 2.0 * wavenumber_per_um(LAMBDA_MIN_NM) * 1.001;
        let s_max = (kappa_max / kappa0).ln_1p();
        let max_nodes = (MAX_TABLE_VALUES / (tile * tile)).min(MAX_NODES);
        let nodes = ((s_max / NODE_STEP).ceil() as usize + 1).clamp(MIN_NODES, max_nodes);
        let node_kappa = |i: usize| kappa0 * (s_max * i as f64 / (nodes - 1) as f64).exp_m1();
        // Each node's FFTs, on the machine's cores.
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(nodes);
        // A 4096^2 map takes about 10 s: say how far it is.
        let progress = &Progress::new("height map spectrum tables", nodes);
        let per_node: Vec<(Vec<f32>, AliasTable, f64)> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || {
                        (t..nodes)
                            .step_by(threads)
                            .map(|i| {
                                let values = node_values(field, tile, node_kappa(i), kappa0);
                                progress.step();
                                (i, values)
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            let mut all: Vec<_> = handles
                .into_iter()
                .flat_map(|h| h.join().expect("a Welch thread"))
                .collect();
            all.sort_by_key(|(i, _)| *i);
            all.into_iter()
                .map(|(_, values)| {
                    let mass: Vec<f64> = values.iter().map(|&v| v as f64).collect();
                    let alias = AliasTable::new(&mass);
                    (values, alias, mass.iter().sum())
                })
                .collect()
        });
        let mut values = Vec::with_capacity(nodes * tile * tile);
        let mut alias = Vec::with_capacity(2 * nodes * tile * tile);
        let mut totals = Vec::with_capacity(nodes);
        for (v, a, total) in per_node {
            values.extend(v);
            alias.extend(a.interleaved);
            totals.push(total);
        }
        let chi2 = chi_squared_table(field, kappa0, s_max);
        SpectrumTable {
            tile,
            tile_um: tile as f64 * field.pixel_um,
            kappa0,
            s_max,
            nodes,
            values,
            alias,
            totals,
            chi2,
            sigma_um,
            correlation_um,
        }
    }

    pub fn memory_bytes(&self) -> usize {
        self.values.len() * 4 + self.chi2.len() * 4 + self.alias.len() * 4 + self.totals.len() * 8
    }

    /// s of node i.
    pub fn node_s(&self, i: usize) -> f64 {
        self.s_max * i as f64 / (self.nodes - 1) as f64
    }
}

/// The default Welch tile: TILE_CORRELATION_LENGTHS correlation lengths,
/// a power of two in DEFAULT_TILE_RANGE, and at most half the map's
/// smaller edge (so that at least 3 x 3 half-overlapping tiles average).
pub fn default_tile(field: &HeightField, correlation_um: f64) -> usize {
    let want = (TILE_CORRELATION_LENGTHS * correlation_um / field.pixel_um).max(1.0);
    let want = (want.min(1e9) as usize).next_power_of_two();
    let edge = field.nx.min(field.ny);
    let half = prev_power_of_two(edge / 2).max(16);
    want.clamp(DEFAULT_TILE_RANGE.0, DEFAULT_TILE_RANGE.1)
        .min(half)
        .min(prev_power_of_two(edge))
}

fn prev_power_of_two(n: usize) -> usize {
    if n == 0 {
        1
    } else {
        1 << (usize::BITS - 1 - n.leading_zeros())
    }
}

/// The tile origins along an edge of `n` samples: every half tile, the
/// last one flush with the edge.
fn tile_starts(n: usize, tile: usize) -> Vec<usize> {
    let mut starts: Vec<usize> = (0..)
        .map(|i| i * tile / 2)
        .take_while(|s| s + tile <= n)
        .collect();
    if starts.last().is_some_and(|&s| s + tile < n) {
        starts.push(n - tile);
    }
    starts
}

/// One node's T (1 + kappa / kappa_0)^4 on the centred frequency grid.
fn node_values(field: &HeightField, tile: usize, kappa: f64, kappa0: f64) -> Vec<f32> {
    let (nx, ny) = (field.nx, field.ny);
    // q = (exp(i kappa h) - chi) / kappa; its kappa -> 0 limit i h.
    let q: Vec<Complex<f32>> = if kappa > 0.0 {
        let p: Vec<Complex<f64>> = field
            .heights_um
            .iter()
            .map(|&h| Complex::from_polar(1.0, kappa * h))
            .collect();
        let chi = p.iter().sum::<Complex<f64>>() / p.len() as f64;
        p.iter()
            .map(|&z| {
                let d = (z - chi) / kappa;
                Complex::new(d.re as f32, d.im as f32)
            })
            .collect()
    } else {
        field
            .heights_um
            .iter()
            .map(|&h| Complex::new(0.0, h as f32))
            .collect()
    };
    let window: Vec<f32> = (0..tile)
        .map(|i| {
            let x = std::f64::consts::TAU * i as f64 / tile as f64;
            (0.5 * (1.0 - x.cos())) as f32
        })
        .collect();
    let window_power: f64 = window
        .iter()
        .map(|&w| (w as f64) * (w as f64))
        .sum::<f64>()
        .powi(2);
    let fft = FftPlanner::<f32>::new().plan_fft_forward(tile);
    let mut scratch = vec![Complex::default(); fft.get_inplace_scratch_len()];
    let mut buffer = vec![Complex::<f32>::default(); tile * tile];
    let mut transposed = vec![Complex::<f32>::default(); tile * tile];
    let mut sum = vec![0.0f64; tile * tile];
    let (xs, ys) = (tile_starts(nx, tile), tile_starts(ny, tile));
    for &y0 in &ys {
        for &x0 in &xs {
            for j in 0..tile {
                let row = &q[(y0 + j) * nx + x0..(y0 + j) * nx + x0 + tile];
                for (i, (b, &z)) in buffer[j * tile..(j + 1) * tile]
                    .iter_mut()
                    .zip(row)
                    .enumerate()
                {
                    *b = z * (window[i] * window[j]);
                }
            }
            // Rows, then columns (as the rows of the transpose).
            fft.process_with_scratch(&mut buffer, &mut scratch);
            transpose(&buffer, &mut transposed, tile);
            fft.process_with_scratch(&mut transposed, &mut scratch);
            // transposed[kx][ky]: accumulate into [ky][kx].
            for kx in 0..tile {
                for ky in 0..tile {
                    sum[ky * tile + kx] += transposed[kx * tile + ky].norm_sqr() as f64;
                }
            }
        }
    }
    // The zero-frequency bin: the map's mean was removed (detrending, and
    // chi), and that mode, shared by every tile, carries the most weight
    // in each tile's DC bin, which reads 11% low on Gaussian maps (8 maps,
    // 256-pixel tiles) while its neighbours are unbiased. It is taken from
    // them instead: the parabola through the bins 1 and 2 away.
    let at = |ix: usize, iy: usize| sum[iy * tile + ix];
    let ring = |d: usize| 0.25 * (at(d, 0) + at(tile - d, 0) + at(0, d) + at(0, tile - d));
    sum[0] = ((4.0 * ring(1) - ring(2)) / 3.0).max(0.0);
    // S = pixel^2 |X|^2 / sum(w^2), averaged over the tiles; T = S / kappa^2
    // (q carries the 1 / kappa); the table's factor (1 + kappa / kappa_0)^4.
    let tiles = (xs.len() * ys.len()) as f64;
    let scale =
        field.pixel_um * field.pixel_um / (window_power * tiles) * (1.0 + kappa / kappa0).powi(4);
    // Centred order: index j holds FFT bin (j + tile / 2) mod tile.
    let half = tile / 2;
    let mut out = vec![0.0f32; tile * tile];
    for jy in 0..tile {
        let by = (jy + half) % tile;
        for jx in 0..tile {
            let bx = (jx + half) % tile;
            out[jy * tile + jx] = (sum[by * tile + bx] * scale) as f32;
        }
    }
    out
}

fn transpose(src: &[Complex<f32>], dst: &mut [Complex<f32>], n: usize) {
    for j in 0..n {
        for i in 0..n {
            dst[i * n + j] = src[j * n + i];
        }
    }
}

/// |chi(kappa)|^2 = |mean exp(i kappa h)|^2 at CHI_NODES values of s,
/// summed over a fine histogram of the heights.
fn chi_squared_table(field: &HeightField, kappa0: f64, s_max: f64) -> Vec<f32> {
    let h = &field.heights_um;
    let lo = h.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = h.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let width = (hi - lo) / HISTOGRAM_BINS as f64;
    let mut counts = vec![0.0f64; HISTOGRAM_BINS];
    for &x in h {
        let bin = if width > 0.0 {
            (((x - lo) / width) as usize).min(HISTOGRAM_BINS - 1)
        } else {
            0
        };
        counts[bin] += 1.0;
    }
    let n = h.len() as f64;
    let bins: Vec<(f64, f64)> = counts
        .iter()
        .enumerate()
        .filter(|(_, &c)| c > 0.0)
        .map(|(i, &c)| (lo + (i as f64 + 0.5) * width, c / n))
        .collect();
    (0..CHI_NODES)
        .map(|i| {
            let kappa = kappa0 * (s_max * i as f64 / (CHI_NODES - 1) as f64).exp_m1();
            let chi: Complex<f64> = bins
                .iter()
                .map(|&(x, w)| Complex::from_polar(w, kappa * x))
                .sum();
            chi.norm_sqr().min(1.0) as f32
        })
        .collect()
}

/// The 1/e length of the map's autocorrelation, averaged over x and y
/// lags (um); half the map's edge where it never falls that low.
pub fn correlation_length_um(field: &HeightField) -> f64 {
    let (nx, ny) = (field.nx, field.ny);
    let h = &field.heights_um;
    let rows: Vec<Vec<f64>> = (0..ny).map(|j| h[j * nx..(j + 1) * nx].to_vec()).collect();
    let cols: Vec<Vec<f64>> = (0..nx)
        .map(|i| (0..ny).map(|j| h[j * nx + i]).collect())
        .collect();
    let lx = one_over_e_lag(&rows);
    let ly = one_over_e_lag(&cols);
    0.5 * (lx + ly) * field.pixel_um
}

/// The lag (in samples, interpolated) where the mean autocorrelation of
/// the lines first falls to 1/e of its value at 0.
fn one_over_e_lag(lines: &[Vec<f64>]) -> f64 {
    let n = lines[0].len();
    let padded = 2 * n;
    let mut planner = FftPlanner::<f64>::new();
    let forward = planner.plan_fft_forward(padded);
    let inverse = planner.plan_fft_inverse(padded);
    let mut acf = vec![0.0; n];
    let mut buffer = vec![Complex::<f64>::default(); padded];
    for line in lines {
        buffer.iter_mut().for_each(|b| *b = Complex::default());
        for (b, &x) in buffer.iter_mut().zip(line) {
            b.re = x;
        }
        forward.process(&mut buffer);
        buffer
            .iter_mut()
            .for_each(|b| *b = Complex::new(b.norm_sqr(), 0.0));
        inverse.process(&mut buffer);
        for (lag, a) in acf.iter_mut().enumerate() {
            // Unbiased: each lag's sum has n - lag products.
            *a += buffer[lag].re / (n - lag) as f64;
        }
    }
    if !(acf[0] > 0.0) {
        return (n / 2) as f64;
    }
    let target = acf[0] / std::f64::consts::E;
    for lag in 1..n / 2 {
        if acf[lag] <= target {
            let (a, b) = (acf[lag - 1], acf[lag]);
            return (lag - 1) as f64 + (a - target) / (a - b);
        }
    }
    (n / 2) as f64
}
