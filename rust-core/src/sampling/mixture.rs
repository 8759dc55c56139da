//! The defensive mixture every strategy is made of. A strategy is a list of
//! equally weighted components (one per wavelength of a spectral path, or
//! the RGB mixture's); each splits its probability between the coherent
//! (mirror) lobe, a defensive part (half cosine-weighted, half uniform over
//! the hemisphere, so that pdf > 0 wherever f > 0) and the model's lobe.
//! rnd[0] picks the component and then its part (remapped inside the chosen
//! interval for the lobe's own sub-choices); rnd[1] and rnd[2] drive the
//! continuous part.

use super::band::RGB_SAMPLING_NODES;
use super::warps::{
    cosine_direction, defensive_density, uniform_direction, unit_interval, ONE_MINUS,
};
use crate::optics::geometry::{normalize_direction, reflect, MIN_COS};
use glam::DVec3;
use smallvec::SmallVec;

/// Share of the non-coherent probability given to the defensive part.
pub const DEFENSIVE_FRACTION: f64 = 0.1;

/// One sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleResult {
    /// Unit direction in the local frame (z = normal).
    pub wo: DVec3,
    /// Solid-angle pdf of the whole strategy at wo; for a coherent sample, the
    /// discrete probability of the coherent lobe; 0 for a failed sample.
    pub pdf: f64,
    /// The coherent (mirror) delta lobe was chosen.
    pub coherent: bool,
}

impl SampleResult {
    pub(crate) fn failed() -> SampleResult {
        SampleResult {
            wo: DVec3::Z,
            pdf: 0.0,
            coherent: false,
        }
    }
}

/// A model's sampling lobe: a normalised density over outgoing directions
/// with its exact solid-angle pdf. `Model` is what the lobe reads from its
/// material at run time (e.g. the fractal's profile).
pub trait Lobe: Clone {
    type Model;
    /// A direction from the sub-choice `t` and the uniforms r1, r2; None
    /// when the draw falls below the horizon.
    fn sample(&self, model: &Self::Model, wi: DVec3, t: f64, r1: f64, r2: f64) -> Option<DVec3>;
    /// Solid-angle density at wo (unit, above the horizon); a lobe may
    /// return 0 where its density is certainly below `negligible`.
    fn pdf(&self, model: &Self::Model, wi: DVec3, wo: DVec3, negligible: f64) -> f64;
}

/// One component of the mixture: coherent lobe, defensive cosine and lobe
/// probabilities summing to 1.
#[derive(Clone)]
pub struct Component<L> {
    pub p_coh: f64,
    pub p_def: f64,
    pub p_lobe: f64,
    pub lobe: Option<L>,
}

impl<L> Component<L> {
    pub fn cosine_only() -> Component<L> {
        Component {
            p_coh: 0.0,
            p_def: 1.0,
            p_lobe: 0.0,
            lobe: None,
        }
    }

    pub fn new(p_coh: f64, rest: f64, lobe: Option<L>) -> Component<L> {
        match lobe {
            Some(lobe) if rest > 0.0 => Component {
                p_coh,
                p_def: DEFENSIVE_FRACTION * rest,
                p_lobe: (1.0 - DEFENSIVE_FRACTION) * rest,
                lobe: Some(lobe),
            },
            _ => Component {
                p_coh,
                p_def: rest,
                p_lobe: 0.0,
                lobe: None,
            },
        }
    }
}

/// The sampling strategy for one incident direction and one mode, built once
/// and used for any number of samples and pdf evaluations.
pub struct Mixture<'a, L: Lobe> {
    model: &'a L::Model,
    wi: DVec3,
    /// Equally weighted components (several in RGB mode).
    components: Components<'a, L>,
}

/// A strategy's components: made for the call, inline (the smooth models'
/// come from their component table: a copy costs less than any cache or
/// allocation), or borrowed from the material's grating table (the RGB
/// rainbow: no copy, and no reference count for the render threads to
/// contend on).
// Inline on purpose: a strategy is built per vertex, and a heap allocation
// per build cost more than moving a few hundred bytes.
#[allow(clippy::large_enum_variant)]
pub enum Components<'a, L> {
    Local(SmallVec<[Component<L>; RGB_SAMPLING_NODES]>),
    Shared(&'a [Component<L>]),
}

impl<L> std::ops::Deref for Components<'_, L> {
    type Target = [Component<L>];
    #[inline]
    fn deref(&self) -> &[Component<L>] {
        match self {
            Components::Local(v) => v,
            Components::Shared(v) => v,
        }
    }
}

impl<'a, L: Lobe> Mixture<'a, L> {
    /// The strategy of `components` for unit wi above the horizon.
    pub fn new(model: &'a L::Model, wi: DVec3, components: Components<'a, L>) -> Self {
        Mixture {
            model,
            wi,
            components,
        }
    }

    /// The strategy with its components copied (a shared one can then be
    /// altered: tests).
    #[cfg(test)]
    pub(crate) fn into_local(self) -> Self {
        let components = match self.components {
            Components::Shared(shared) => Components::Local(shared.iter().cloned().collect()),
            local => local,
        };
        Mixture { components, ..self }
    }

    #[cfg(test)]
    pub(crate) fn components_mut(&mut self) -> &mut [Component<L>] {
        match &mut self.components {
            Components::Local(v) => v,
            Components::Shared(_) => panic!("a shared strategy cannot be altered"),
        }
    }

    /// The strategy of an incident direction that has none (below the
    /// horizon, not finite): every sample fails, every pdf is 0.
    pub fn empty(model: &'a L::Model) -> Self {
        Mixture::new(model, DVec3::Z, Components::Local(SmallVec::new()))
    }

    /// Discrete probability of choosing the coherent lobe.
    pub fn coherent_probability(&self) -> f64 {
        if self.components.is_empty() {
            return 0.0;
        }
        let sum: f64 = self.components.iter().map(|c| c.p_coh).sum();
        sum / self.components.len() as f64
    }

    /// Solid-angle pdf of the non-coherent part at wo (0 below the horizon).
    pub fn pdf(&self, wo: DVec3) -> f64 {
        if self.components.is_empty() {
            return 0.0;
        }
        let Some(wo) = normalize_direction(wo) else {
            return 0.0;
        };
        if !(wo.z > MIN_COS) {
            return 0.0;
        }
        let defensive: f64 =
            self.components.iter().map(|c| c.p_def).sum::<f64>() * defensive_density(wo.z);
        let mut sum = defensive;
        for c in self.components.iter() {
            if let Some(lobe) = &c.lobe {
                // Lobe densities 1e-17 below the defensive part do not change
                // the f64 sum.
                let negligible = 1e-17 * defensive / c.p_lobe;
                sum += c.p_lobe * lobe.pdf(self.model, self.wi, wo, negligible);
            }
        }
        let pdf = sum / self.components.len() as f64;
        // A sum that overflowed (densities near f64::MAX at the exact mirror
        // direction of a fractal with tiny hurst) is clamped like eval's
        // outputs, not zeroed: pdf must stay > 0 wherever f > 0.
        if pdf.is_nan() {
            0.0
        } else {
            pdf.clamp(0.0, f64::MAX)
        }
    }

    pub fn sample(&self, rnd: [f64; 3]) -> SampleResult {
        self.sample_mapped(rnd, |wo| wo)
    }

    /// `sample`, with a glossy direction mapped by `map` (e.g. rounded to
    /// the caller's precision) before its pdf is taken, so that the pdf is
    /// the one at the direction the caller gets.
    pub fn sample_mapped(&self, rnd: [f64; 3], map: impl Fn(DVec3) -> DVec3) -> SampleResult {
        match self.sample_direction(rnd) {
            Some((wo, true)) => SampleResult {
                wo,
                pdf: self.coherent_probability(),
                coherent: true,
            },
            Some((wo, false)) => {
                let wo = map(wo);
                let pdf = self.pdf(wo);
                if pdf > 0.0 && pdf.is_finite() {
                    SampleResult {
                        wo,
                        pdf,
                        coherent: false,
                    }
                } else {
                    SampleResult::failed()
                }
            }
            None => SampleResult::failed(),
        }
    }

    /// The direction `sample` draws and whether it is the coherent lobe's,
    /// without its pdf; None when the sample failed.
    fn sample_direction(&self, rnd: [f64; 3]) -> Option<(DVec3, bool)> {
        let count = self.components.len();
        if count == 0 {
            return None;
        }
        let [r0, r1, r2] = rnd.map(unit_interval);
        let scaled = r0 * count as f64;
        let j = (scaled as usize).min(count - 1);
        let mut r = (scaled - j as f64).clamp(0.0, ONE_MINUS);
        let c = &self.components[j];
        if r < c.p_coh {
            return Some((reflect(self.wi), true));
        }
        r -= c.p_coh;
        let wo = if r < c.p_def {
            // Half cosine-weighted, half uniform over the hemisphere.
            if r < 0.5 * c.p_def {
                Some(cosine_direction(r1, r2))
            } else {
                Some(uniform_direction(r1, r2))
            }
        } else {
            match &c.lobe {
                Some(lobe) => {
                    let t = ((r - c.p_def) / c.p_lobe).clamp(0.0, ONE_MINUS);
                    lobe.sample(self.model, self.wi, t, r1, r2)
                }
                None => None,
            }
        };
        wo.map(|wo| (wo, false))
    }
}
