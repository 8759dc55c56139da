//! The structure the solver sees: a superstrate, lamellar layers (permittivity
//! piecewise constant over one period, constant in depth) and a substrate;
//! and how a grating profile becomes such layers (exactly for `Rect`, by
//! staircase slicing for `Sine` and `Tabulated`).

use faer::{c64, Mat};

use crate::optics::fresnel::metal_index;
use crate::optics::metals::MetalTable;
use crate::optics::profile::Profile;
use crate::StamError;

/// A medium's optical constants.
#[derive(Clone, Copy)]
pub enum Medium {
    /// A measured metal (refractive index interpolated linearly in wavelength).
    Metal(&'static MetalTable),
    /// A constant complex refractive index eta + i k (k >= 0 absorbs).
    Index { eta: f64, k: f64 },
}

impl std::fmt::Debug for Medium {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Medium::Metal(table) => write!(f, "Metal({})", table.name),
            Medium::Index { eta, k } => write!(f, "Index({eta} + {k}i)"),
        }
    }
}

impl Medium {
    /// Relative permittivity (eta + i k)^2 at `lambda_nm` (time convention
    /// exp(-i omega t): Im >= 0 absorbs).
    pub fn permittivity(&self, lambda_nm: f64) -> c64 {
        let (eta, k) = match *self {
            Medium::Metal(table) => metal_index(table, lambda_nm),
            Medium::Index { eta, k } => (eta, k),
        };
        let n = c64::new(eta, k);
        n * n
    }
}

/// One lamellar layer: `cells[j] = (end, eps)` fills [end of cell j-1, end)
/// of the period (fractions of the period, the first cell starting at 0, the
/// last ending at 1).
#[derive(Clone, Debug)]
pub struct Layer {
    pub thickness_um: f64,
    pub cells: Vec<(f64, c64)>,
}

impl Layer {
    pub fn homogeneous(thickness_um: f64, eps: c64) -> Layer {
        Layer {
            thickness_um,
            cells: vec![(1.0, eps)],
        }
    }

    /// The one permittivity of a layer without structure.
    pub fn uniform_permittivity(&self) -> Option<c64> {
        let first = self.cells[0].1;
        self.cells.iter().all(|&(_, e)| e == first).then_some(first)
    }

    /// Fourier coefficient n of f(eps(x)) over one period, exact for the
    /// piecewise-constant cells: (1/Lam) int f(eps) exp(-i 2 pi n x / Lam) dx.
    fn coefficient(&self, n: i64, f: impl Fn(c64) -> c64) -> c64 {
        let mut start = 0.0;
        let mut sum = c64::new(0.0, 0.0);
        for &(end, eps) in &self.cells {
            let weight = if n == 0 {
                c64::new(end - start, 0.0)
            } else {
                // (e^{-i 2 pi n a} - e^{-i 2 pi n b}) / (i 2 pi n)
                let w = -2.0 * std::f64::consts::PI * n as f64;
                let ea = c64::from_polar(1.0, w * start);
                let eb = c64::from_polar(1.0, w * end);
                (ea - eb) / c64::new(0.0, -w)
            };
            sum += f(eps) * weight;
            start = end;
        }
        sum
    }

    /// Toeplitz matrix [[f(eps)]]_{mp} = coefficient(m - p) over the
    /// `size` = 2N + 1 retained orders.
    pub fn toeplitz(&self, size: usize, f: impl Fn(c64) -> c64) -> Mat<c64> {
        let n_max = size as i64 - 1;
        let coefficients: Vec<c64> = (-n_max..=n_max).map(|n| self.coefficient(n, &f)).collect();
        Mat::from_fn(size, size, |r, c| {
            coefficients[(r as i64 - c as i64 + n_max) as usize]
        })
    }
}

/// Everything between the incidence medium and the substrate, at one
/// wavelength.
#[derive(Clone, Debug)]
pub struct Stack {
    pub period_um: f64,
    /// Real refractive index of the incidence medium (air: 1).
    pub superstrate_index: f64,
    /// From the superstrate down.
    pub layers: Vec<Layer>,
    pub substrate_eps: c64,
}

impl Stack {
    pub fn validate(&self) -> Result<(), StamError> {
        if !(self.period_um > 0.0 && self.period_um.is_finite()) {
            return Err(StamError::new(format!(
                "period_um must be a positive finite length, got {}",
                self.period_um
            )));
        }
        if !(self.superstrate_index >= 1.0 && self.superstrate_index < 10.0) {
            return Err(StamError::new(format!(
                "cover_eta (the incidence medium's index) must be in [1, 10), got {}",
                self.superstrate_index
            )));
        }
        let finite = |e: c64| e.re.is_finite() && e.im.is_finite() && e.im >= 0.0;
        if !finite(self.substrate_eps) {
            return Err(StamError::new(format!(
                "the substrate's permittivity must be finite and not gain (Im >= 0), got {}",
                self.substrate_eps
            )));
        }
        for (i, layer) in self.layers.iter().enumerate() {
            if !(layer.thickness_um >= 0.0 && layer.thickness_um.is_finite()) {
                return Err(StamError::new(format!(
                    "layer {i}: thickness must be finite and >= 0 um, got {}",
                    layer.thickness_um
                )));
            }
            let mut start = 0.0;
            for &(end, eps) in &layer.cells {
                if !(end > start && end <= 1.0 && finite(eps)) {
                    return Err(StamError::new(format!(
                        "layer {i}: cells must end in increasing order within the period \
                         with finite permittivities, got end {end} after {start}, eps {eps}"
                    )));
                }
                start = end;
            }
            if start != 1.0 {
                return Err(StamError::new(format!(
                    "layer {i}: the cells end at {start} of the period, not 1"
                )));
            }
        }
        Ok(())
    }
}

/// A grating: a height profile over one period, cut into `slices` layers of
/// equal thickness where it is not a rectangle, on a substrate of `metal`.
#[derive(Clone, Debug)]
pub struct Grating {
    pub period_um: f64,
    pub profile: Profile,
    pub metal: Medium,
    /// Staircase layers for `Sine` and `Tabulated` (a `Rect` is one layer).
    pub slices: usize,
}

impl Grating {
    /// Peak-to-valley height of the profile.
    pub fn depth_um(&self) -> f64 {
        match &self.profile {
            Profile::Rect { height_um, .. } | Profile::Sine { height_um } => *height_um,
            Profile::Tabulated { heights_um } => {
                let lo = heights_um.iter().cloned().fold(f64::INFINITY, f64::min);
                let hi = heights_um.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                hi - lo
            }
        }
    }

    /// The layers at `lambda_nm` under a medium of index `superstrate_index`.
    pub fn stack(&self, lambda_nm: f64, superstrate_index: f64) -> Stack {
        let metal = self.metal.permittivity(lambda_nm);
        let cover = c64::new(superstrate_index * superstrate_index, 0.0);
        let depth = self.depth_um();
        let layers = match &self.profile {
            Profile::Rect { width_um, .. } => {
                let fill = (width_um / self.period_um).clamp(0.0, 1.0);
                vec![lamellar(depth, &[(0.0, fill)], metal, cover)]
            }
            _ if depth <= 0.0 => Vec::new(),
            profile => {
                let slices = self.slices.max(1);
                let thickness = depth / slices as f64;
                (0..slices)
                    .map(|j| {
                        // Metal where the profile stands above the slice's
                        // middle (slices from the top down).
                        let level = depth * (1.0 - (j as f64 + 0.5) / slices as f64);
                        lamellar(thickness, &above(profile, level), metal, cover)
                    })
                    .collect()
            }
        };
        Stack {
            period_um: self.period_um,
            superstrate_index,
            layers,
            substrate_eps: metal,
        }
    }
}

/// Intervals of the period (fractions, within [0, 1]) where the profile,
/// measured from its lowest point, stands above `level`.
fn above(profile: &Profile, level: f64) -> Vec<(f64, f64)> {
    match profile {
        Profile::Rect { .. } => unreachable!("a rect grating is one layer"),
        Profile::Sine { height_um } => {
            // h(x) = (b/2)(1 + cos 2 pi x) >= level  <=>  |x| <= acos(c) / 2 pi.
            let c = (2.0 * level / height_um - 1.0).clamp(-1.0, 1.0);
            let a = c.acos() / (2.0 * std::f64::consts::PI);
            vec![(0.0, a), (1.0 - a, 1.0)]
        }
        Profile::Tabulated { heights_um } => {
            let lo = heights_um.iter().cloned().fold(f64::INFINITY, f64::min);
            let n = heights_um.len();
            let mut runs = Vec::new();
            let mut open: Option<f64> = None;
            // Linear between samples j and j + 1 (the last back to the first).
            for j in 0..n {
                let (h0, h1) = (heights_um[j] - lo, heights_um[(j + 1) % n] - lo);
                let (x0, x1) = (j as f64 / n as f64, (j + 1) as f64 / n as f64);
                if j == 0 && h0 >= level {
                    open = Some(0.0);
                }
                if (h0 >= level) != (h1 >= level) {
                    let x = x0 + (x1 - x0) * (level - h0) / (h1 - h0);
                    match open.take() {
                        Some(start) => runs.push((start, x)),
                        None => open = Some(x),
                    }
                }
            }
            if let Some(start) = open {
                runs.push((start, 1.0));
            }
            runs
        }
    }
}

/// A layer of `fill` between the `inside` intervals and `outside` elsewhere.
fn lamellar(thickness_um: f64, inside: &[(f64, f64)], fill: c64, outside: c64) -> Layer {
    let mut cells: Vec<(f64, c64)> = Vec::new();
    let mut push = |end: f64, eps: c64| {
        if let Some(last) = cells.last_mut() {
            if end <= last.0 {
                return;
            }
            if last.1 == eps {
                last.0 = end;
                return;
            }
        } else if end <= 0.0 {
            return;
        }
        cells.push((end, eps));
    };
    let mut at = 0.0;
    for &(a, b) in inside {
        push(a, outside);
        push(b, fill);
        at = b;
    }
    if at < 1.0 {
        push(1.0, outside);
    }
    if cells.is_empty() {
        cells.push((1.0, outside));
    }
    Layer {
        thickness_um,
        cells,
    }
}
