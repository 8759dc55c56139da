//! `"orders": "rigorous"`: each order's power from Maxwell's equations
//! instead of Stam's formula (docs/rigorous.md, "In a material").
//!
//! Stam's kernel gives order n the lobe F^2 G |c_n(k w)|^2 / w^2 times a
//! Gaussian of the coherence length. Here the lobe keeps its Gaussian (the
//! illumination's coherence, which Maxwell's equations for a perfectly
//! periodic grating do not know) and its power is the order's rigorous
//! efficiency eta_n, tabulated once per grating (`rigorous::table`):
//!
//! ```text
//! f = sum_n eta_n (k^2 l^2 / pi) exp(-l^2 [(k u - 2 pi n / Lam)^2 + k^2 v^2])
//! ```
//!
//! The Gaussian integrates to 1 over the projected hemisphere
//! (cos_o d omega_o = du dv), so order n reflects eta_n of the incident
//! light, and the orders together what the solver says the grating
//! reflects: no Fresnel term, no G, no energy table.
//!
//! A lobe is read at the incidence of the exact order pair nearest to
//! (wi, wo): both directions moved by half the pair's distance from the
//! order (in u, and in v to the mirror), which keeps the lobe's centre
//! where the solver puts the order. The efficiency is the mean of the
//! table at that incidence seen from wi and from wo, so that f(wi, wo) =
//! f(wo, wi) exactly (the grating's reciprocity, which the solver meets to
//! 4e-5, would otherwise hold only to the table's interpolation error).
//!
//! Orders: the solver's m (kx_m = kx + m lambda / Lam for the incident
//! wave, which travels along -wi) is Stam's -n (u = -(wi.x + wo.x) =
//! n lambda / Lam at the order).
//!
//! A transparent cover of index n (`cover_eta`, a real disc's
//! polycarbonate) is a flat dielectric interface above the grating, far
//! enough for its reflections to add as powers: it reflects R(cos_i) (the
//! unpolarised Fresnel reflectance of the index: a mirror lobe, the
//! material's coherent lobe), lets 1 - R(cos_i) in, the grating diffracts
//! inside the medium (the table is solved with the cover as incidence
//! medium; the tangential wavevector, hence (kx, ky), is the same inside and
//! out), and an order leaves with 1 - R(cos_o); orders that meet the cover
//! beyond its critical angle (|k_t| > 1) stay inside. Left out: the light
//! the cover reflects back onto the grating (R ~ 4-5% of each order, which
//! would re-diffract) and the polarisation through the two interfaces (each
//! is taken unpolarised).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use glam::DVec3;

use super::rgb::GIVEN_BROAD_NODES;
use super::rigorous_grid::PairGrid;
use super::{PeriodicSurface, Profile};
use crate::error::StamError;
use crate::optics::fresnel::{conductor_reflectance, Fresnel};
use crate::rigorous::{polarisation, table, EfficiencyTable, Grating, Medium, TableSpec};
use crate::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Staircase layers for smooth (sine and tabulated) profiles.
const SLICES: usize = 16;
/// Largest |k_t| at which a table is read (its rows end just inside the
/// incidence disc).
const DISC_EDGE: f64 = 0.9995;

/// A grating's rigorous efficiencies, shared between materials of the same
/// grating (the table cache).
#[derive(Clone, Debug)]
pub struct RigorousOrders {
    table: Arc<EfficiencyTable>,
    period_um: f64,
    /// Index of the transparent cover (1: none).
    cover_eta: f64,
    /// What is derived from the table on first use and shared by its
    /// materials (`derived_cell`).
    derived: Arc<Derived>,
    /// What the table was built from: the polarised table is built from
    /// the same on first use.
    grating: Grating,
    spec: TableSpec,
}

/// Resamplings of a table, each built on first use.
#[derive(Debug, Default)]
struct Derived {
    /// Order 0 at the RGB broad rule's wavelengths.
    mirror: OnceLock<MirrorSpectra>,
    /// Every order's pair efficiencies for the programs.
    pairs: OnceLock<Option<Arc<PairGrid>>>,
    /// The table with each order's Mueller matrix (polarised renders),
    /// or why there is none.
    polarised: OnceLock<Result<Arc<EfficiencyTable>, String>>,
}

/// Nodes per axis of `MirrorSpectra`'s grid, over (|kx|, |ky|) in
/// [0, MIRROR_REACH]^2; pairs with |(kx, ky)| beyond MIRROR_TRUST read the
/// table at each wavelength (grazing incidence, where order 0 changes
/// fastest).
pub(crate) const MIRROR_GRID_X: usize = 256;
pub(crate) const MIRROR_GRID_Y: usize = 64;
const MIRROR_REACH: f64 = 0.92;
const MIRROR_TRUST: f64 = 0.9;

/// Order 0's efficiency at the wavelengths of the RGB broad-peak rule
/// (`PeriodicSurface::given_broad_wavelengths`) over a grid of the pair's
/// (|kx|, |ky|). Near the mirror direction, where the Gaussian of order 0
/// is broad in wavelength, the RGB integral would read the table at each
/// of these wavelengths for every pair; order 0's incidence does not
/// depend on the wavelength (u_0 = 0), so one bilinear read of this grid
/// gives the whole spectrum.
#[derive(Debug)]
struct MirrorSpectra {
    /// [ix][iy][j]: |kx| = ix hx, |ky| = iy hy (h = MIRROR_REACH / (G - 1)
    /// on each axis's G).
    values: Vec<f32>,
}

/// The medium of a material's Fresnel term: the solver needs the metal's
/// complex index, which a constant reflectance does not give.
fn medium(fresnel: &Fresnel) -> Result<Medium, String> {
    match fresnel {
        Fresnel::Metal { table, .. } => Ok(Medium::Metal(table)),
        Fresnel::ComplexIndex { eta, k } => Ok(Medium::Index { eta: *eta, k: *k }),
        Fresnel::Constant(r) => Err(format!(
            "\"orders\": \"rigorous\" needs the grating's material: set 'fresnel' to a metal's name or {{\"eta\": ..., \"k\": ...}} (got the constant reflectance {r})"
        )),
    }
}

/// The table grid of a material: the band, 20 x 41 rows over (lambda, kx),
/// about 3 ky nodes per 0.25 of sqrt(ky^2 - ky_m^2) between anomalies, the
/// cover (1: none) as the incidence medium. On the compact disc (N = 20)
/// 3.8-5.7 s to build on 2 cores, per-order error rms 0.009, p99 0.037
/// (docs/rigorous.md, "Measured accuracy").
pub fn table_spec(fourier_orders: usize, cover_eta: f64) -> TableSpec {
    TableSpec {
        lambda_min_nm: LAMBDA_MIN_NM,
        lambda_max_nm: LAMBDA_MAX_NM,
        n_lambda: 20,
        n_kx: 41,
        nodes_per_gap: 3,
        orders: fourier_orders,
        cover_eta,
        polarised: false,
    }
}

impl RigorousOrders {
    /// The efficiencies of `profile` with period `period_um` on the material
    /// of `fresnel`, from the cache or built (seconds to a minute, with
    /// progress on stderr).
    pub fn new(
        period_um: f64,
        profile: &Profile,
        fresnel: &Fresnel,
        fourier_orders: usize,
        cover_eta: f64,
    ) -> Result<RigorousOrders, StamError> {
        let grating = Grating {
            period_um,
            profile: profile.clone(),
            metal: medium(fresnel).map_err(StamError::new)?,
            slices: SLICES,
        };
        let spec = table_spec(fourier_orders, cover_eta);
        let table = table::table(&grating, &spec)?;
        Ok(RigorousOrders {
            derived: derived_cell(&table),
            table,
            period_um,
            cover_eta,
            grating,
            spec,
        })
    }

    /// Whether the orders have a polarisation to export: every grating
    /// without a cover (a cover's two interfaces are taken unpolarised, see
    /// the module doc, so its orders' polarisation would be half a model).
    pub fn polarizes(&self) -> bool {
        !self.has_cover()
    }

    /// The table with Mueller matrices: built on first use (a second solve
    /// of every node, with progress on stderr, then kept on disk like the
    /// efficiencies), shared by the materials of the grating.
    fn polarised_table(&self) -> Option<&EfficiencyTable> {
        if !self.polarizes() {
            return None;
        }
        let built = self.derived.polarised.get_or_init(|| {
            let spec = TableSpec {
                polarised: true,
                ..self.spec.clone()
            };
            table::table(&self.grating, &spec).map_err(|e| e.to_string())
        });
        match built {
            Ok(t) => Some(t),
            Err(e) => {
                static WARNED: OnceLock<()> = OnceLock::new();
                WARNED.get_or_init(|| {
                    eprintln!("stam: no polarised rigorous table ({e}): the orders depolarize")
                });
                None
            }
        }
    }

    /// Stam's order n's Mueller matrix (the solver's order -n) for light
    /// arriving from `from` and leaving along `to` (unit, above the
    /// horizon, the material's frame), at the incidence of the exact order
    /// pair nearest to them, in the groove bases of the two directions of
    /// travel (`rigorous::polarisation`; in the material's frame the groove
    /// basis of a direction d is y x d normalised, up to a sign that does not
    /// change a Mueller matrix). [0][0] is the order's unpolarised
    /// efficiency. None without a polarised table.
    pub fn order_mueller(
        &self,
        n: i64,
        lambda_nm: f64,
        from: DVec3,
        to: DVec3,
    ) -> Option<polarisation::Mueller> {
        let table = self.polarised_table()?;
        // The solver's frame is the material's turned half a turn about x
        // (z into the grating): the incident wave's tangential wavevector
        // is (-from.x, from.y), the outgoing one's (to.x, -to.y). The
        // exact pair of order m = -n moves both by half their distance
        // from kx_out = kx_in + m lambda / Lam, ky_out = ky_in.
        let m = -n;
        let step = lambda_nm * 1e-3 / self.period_um;
        let kx = 0.5 * (to.x - from.x - m as f64 * step);
        let ky = 0.5 * (from.y - to.y);
        let (kx, ky) = within_disc(kx, ky);
        table.mueller(lambda_nm, kx, ky, m)
    }

    /// The cover's reflectance at an incidence cosine (0 without a cover):
    /// what its mirror lobe reflects.
    pub fn cover_reflectance(&self, cos_theta: f64) -> f64 {
        if self.cover_eta > 1.0 {
            conductor_reflectance(cos_theta, self.cover_eta, 0.0)
        } else {
            0.0
        }
    }

    /// The cover's index (1: none).
    pub fn cover_eta(&self) -> f64 {
        self.cover_eta
    }

    pub fn has_cover(&self) -> bool {
        self.cover_eta > 1.0
    }

    /// Order n's power in f for the pair: its efficiency through the
    /// cover's two interfaces (1 - R in, 1 - R out).
    pub fn power(&self, n: i64, lambda_nm: f64, wi: DVec3, wo: DVec3) -> f64 {
        self.through(wi, wo) * self.efficiency(n, lambda_nm, wi, wo)
    }

    /// What the cover lets through on the way in and out (1 without one).
    fn through(&self, wi: DVec3, wo: DVec3) -> f64 {
        (1.0 - self.cover_reflectance(wi.z)) * (1.0 - self.cover_reflectance(wo.z))
    }

    pub fn table(&self) -> &EfficiencyTable {
        &self.table
    }

    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<RigorousOrders>()
            + self.table.memory_bytes()
            + self.derived.mirror.get().map_or(0, |m| m.values.len() * 4)
            + self
                .derived
                .pairs
                .get()
                .and_then(|g| g.as_ref())
                .map_or(0, |g| g.memory_bytes())
    }

    /// Order 0's efficiency for a pair whose half difference of tangential
    /// directions is (kx, ky) (`efficiency(0, ..)`: the table at (kx, ky)
    /// from one side and at (-kx, ky) from the other).
    fn order_zero(&self, lambda_nm: f64, kx: f64, ky: f64) -> f64 {
        let read = |kx: f64| {
            let (kx, ky) = within_disc(kx, ky);
            self.table.efficiency(lambda_nm, kx, ky, 0)
        };
        if self.table.symmetric() {
            read(kx)
        } else {
            0.5 * (read(kx) + read(-kx))
        }
    }

    fn mirror_spectra(&self) -> &MirrorSpectra {
        self.derived.mirror.get_or_init(|| {
            let lambdas = PeriodicSurface::given_broad_wavelengths();
            let (gx, gy, nl) = (MIRROR_GRID_X, MIRROR_GRID_Y, lambdas.len());
            let (hx, hy) = (
                MIRROR_REACH / (gx - 1) as f64,
                MIRROR_REACH / (gy - 1) as f64,
            );
            let mut values = vec![0.0f32; gx * gy * nl];
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
            let per = gx.div_ceil(threads);
            std::thread::scope(|scope| {
                for (chunk, block) in values.chunks_mut(per * gy * nl).enumerate() {
                    scope.spawn(move || {
                        for (k, v) in block.iter_mut().enumerate() {
                            let ix = chunk * per + k / (gy * nl);
                            let (iy, j) = ((k / nl) % gy, k % nl);
                            *v = self.order_zero(lambdas[j], ix as f64 * hx, iy as f64 * hy) as f32;
                        }
                    });
                }
            });
            MirrorSpectra { values }
        })
    }

    /// `power(0, lambda_j, wi, wo)` at every wavelength lambda_j of the RGB
    /// broad rule: read bilinearly from the grid of order 0's spectra, or
    /// from the table at grazing incidence.
    pub fn order_zero_at_nodes(&self, wi: DVec3, wo: DVec3) -> [f64; GIVEN_BROAD_NODES] {
        let mut out = [0.0; GIVEN_BROAD_NODES];
        let (kx, ky) = (0.5 * (wo.x - wi.x), 0.5 * (wi.y - wo.y));
        let through = self.through(wi, wo);
        if kx.hypot(ky) > MIRROR_TRUST {
            let lambdas = PeriodicSurface::given_broad_wavelengths();
            for (o, &lambda) in out.iter_mut().zip(lambdas) {
                *o = through * self.efficiency(0, lambda, wi, wo);
            }
            return out;
        }
        let m = self.mirror_spectra();
        let cell = |k: f64, g: usize| {
            let t = (k.abs() / MIRROR_REACH * (g - 1) as f64).min((g - 1) as f64);
            let i = (t as usize).min(g - 2);
            (i, t - i as f64)
        };
        let ((ix, tx), (iy, ty)) = (cell(kx, MIRROR_GRID_X), cell(ky, MIRROR_GRID_Y));
        let nl = GIVEN_BROAD_NODES;
        let at = |ix: usize, iy: usize| &m.values[(ix * MIRROR_GRID_Y + iy) * nl..][..nl];
        let (a, b, c, d) = (
            at(ix, iy),
            at(ix, iy + 1),
            at(ix + 1, iy),
            at(ix + 1, iy + 1),
        );
        let w = [
            through * (1.0 - tx) * (1.0 - ty),
            through * (1.0 - tx) * ty,
            through * tx * (1.0 - ty),
            through * tx * ty,
        ];
        for (j, o) in out.iter_mut().enumerate() {
            *o = w[0] * a[j] as f64 + w[1] * b[j] as f64 + w[2] * c[j] as f64 + w[3] * d[j] as f64;
        }
        out
    }

    /// Every order's pair efficiencies resampled for the programs (built on
    /// first use, shared by the materials of the table).
    /// None where the grid would be too large (periods above about 4 um).
    pub(crate) fn pair_grid(&self) -> Option<&PairGrid> {
        self.pair_grid_cell().as_deref()
    }

    /// `pair_grid`, shared.
    pub(crate) fn pair_grid_arc(&self) -> Option<Arc<PairGrid>> {
        self.pair_grid_cell().clone()
    }

    fn pair_grid_cell(&self) -> &Option<Arc<PairGrid>> {
        self.derived
            .pairs
            .get_or_init(|| PairGrid::build(self, self.period_um).map(Arc::new))
    }

    /// The efficiency of Stam's order n for the pair (unit wi, wo above
    /// the horizon) at `lambda_nm`: the table at the nearest exact pair's
    /// incidence, from both sides (see the module doc).
    pub fn efficiency(&self, n: i64, lambda_nm: f64, wi: DVec3, wo: DVec3) -> f64 {
        self.pair_efficiency(n, lambda_nm, 0.5 * (wo.x - wi.x), 0.5 * (wi.y - wo.y))
    }

    /// `efficiency` by the exact pair's own coordinates: moved onto order
    /// n (u_n = n lambda / Lam), wi and wo have the incident tangential
    /// wavevectors (u_n / 2 + c, ky) and (u_n / 2 - c, -ky), c =
    /// (wo.x - wi.x) / 2 and ky = (wi.y - wo.y) / 2 (the incident wave
    /// travels along -w). Even in c (the two reads swap) and in ky (the
    /// table's symmetry); a symmetric grating's order -n equals its n.
    pub fn pair_efficiency(&self, n: i64, lambda_nm: f64, c: f64, ky: f64) -> f64 {
        let u_n = n as f64 * lambda_nm * 1e-3 / self.period_um;
        let from = |kx: f64| {
            let (kx, ky) = within_disc(kx, ky);
            self.table.efficiency(lambda_nm, kx, ky, -n)
        };
        // Order 0 reads (c, ky) from one side and (-c, ky) from the
        // other: the same read on a symmetric grating's table.
        if n == 0 && self.table.symmetric() {
            return from(c);
        }
        0.5 * (from(0.5 * u_n + c) + from(0.5 * u_n - c))
    }
}

/// The resamplings of a table, one set per table in the process (keyed by
/// the table's address, which the entry keeps from reuse by holding the
/// table).
fn derived_cell(table: &Arc<EfficiencyTable>) -> Arc<Derived> {
    type Cell = (Arc<EfficiencyTable>, Arc<Derived>);
    static CELLS: OnceLock<Mutex<HashMap<usize, Cell>>> = OnceLock::new();
    let cells = CELLS.get_or_init(|| Mutex::new(HashMap::new()));
    let key = Arc::as_ptr(table) as usize;
    let mut cells = cells.lock().unwrap_or_else(|e| e.into_inner());
    let (_, cell) = cells
        .entry(key)
        .or_insert_with(|| (table.clone(), Arc::new(Derived::default())));
    cell.clone()
}

/// (kx, ky) moved radially inside the table's disc.
fn within_disc(kx: f64, ky: f64) -> (f64, f64) {
    let r = (kx * kx + ky * ky).sqrt();
    if r > DISC_EDGE {
        let s = DISC_EDGE / r;
        (kx * s, ky * s)
    } else {
        (kx, ky)
    }
}
