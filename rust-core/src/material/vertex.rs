//! The queries of one path vertex, as a renderer makes them: f towards a
//! light with the density of the BSDF's own strategy there (for multiple
//! importance sampling), and one BSDF sample with its value.
//!
//! A path carries either RGB or N wavelengths (Mitsuba's spectral variants:
//! 4). For N wavelengths the strategy is the one-sample mixture of the N
//! per-wavelength strategies (include/stam.h): the sample is drawn with one
//! wavelength, picked by rnd[0], and every wavelength is weighted by the
//! mixture density. Doing the whole vertex in one call shares what the N
//! wavelengths have in common (the pair geometry, the normalised
//! directions) instead of repeating it per wavelength and per query.

use super::Brdf;
use crate::models::Strategy;
use crate::optics::geometry::PairGeometry;
use crate::sampling::SampleResult;
use glam::DVec3;

/// The channels of a path: RGB (3 values), or its wavelengths in nm.
#[derive(Clone, Copy, Debug)]
pub enum Channels<'a> {
    Rgb,
    Wavelengths(&'a [f64]),
}

impl Channels<'_> {
    /// Values per query: 3 for RGB, N for N wavelengths.
    pub fn count(&self) -> usize {
        match self {
            Channels::Rgb => 3,
            Channels::Wavelengths(l) => l.len(),
        }
    }
}

impl Brdf {
    /// The strategy of a vertex at wi for a path with these channels: RGB
    /// mode's, or the mixture of the wavelengths' strategies. Each of those
    /// is one equally weighted component (or the RGB mixture), so the
    /// mixture is a single strategy whose first uniform picks the sampling
    /// wavelength.
    pub fn vertex_strategy(&self, wi: DVec3, channels: Channels) -> Strategy<'_> {
        match channels {
            Channels::Rgb => self.sampler(wi, None),
            Channels::Wavelengths(lambdas) => self.mixture_sampler(wi, lambdas),
        }
    }

    /// f(wi, wo) per channel (without cos and without the coherent lobe)
    /// into `f` (at least `channels.count()` values).
    pub fn eval_channels(&self, wi: DVec3, wo: DVec3, channels: Channels, f: &mut [f64]) {
        match channels {
            Channels::Rgb => f[..3].copy_from_slice(&self.eval_rgb(wi, wo)),
            Channels::Wavelengths(lambdas) => {
                let out = &mut f[..lambdas.len()];
                match PairGeometry::new(wi, wo) {
                    Some(geom) => {
                        let fresnel = self.fresnel_at(&geom);
                        let energy = self.pair_energy(geom.wi, geom.wo);
                        for (o, &lambda) in out.iter_mut().zip(lambdas) {
                            *o = self.eval_spectral_scaled(&geom, lambda, &fresnel, &energy);
                        }
                    }
                    None => out.fill(0.0),
                }
            }
        }
    }

    /// Density of `sample_channels`' strategy at wo (non-coherent part):
    /// the RGB strategy's, or the mean over the wavelengths' strategies.
    pub fn pdf_channels(&self, wi: DVec3, wo: DVec3, channels: Channels) -> f64 {
        self.vertex_strategy(wi, channels).pdf(wo)
    }

    /// Probability that `sample_channels` picks the coherent lobe.
    pub fn coherent_probability_channels(&self, wi: DVec3, channels: Channels) -> f64 {
        self.vertex_strategy(wi, channels).coherent_probability()
    }

    /// One sample for a path with these channels (see `sample_with`).
    pub fn sample_channels(
        &self,
        wi: DVec3,
        channels: Channels,
        rnd: [f64; 3],
        round: impl Fn(DVec3) -> DVec3,
        value: &mut [f64],
    ) -> SampleResult {
        let strategy = self.vertex_strategy(wi, channels);
        self.sample_with(&strategy, wi, channels, rnd, round, value)
    }

    /// One sample of `strategy` (made for wi and channels). `value`
    /// receives, per channel, f at the sampled wo (glossy) or the coherent
    /// lobe's reflectance (coherent); the result's pdf is the strategy's
    /// density at the sampled wo as the caller will see it (`round` maps a
    /// direction to the caller's precision), or for a coherent sample its
    /// probability of the coherent lobe. A failed sample has pdf 0 and value
    /// 0.
    pub fn sample_with(
        &self,
        strategy: &Strategy,
        wi: DVec3,
        channels: Channels,
        rnd: [f64; 3],
        round: impl Fn(DVec3) -> DVec3,
        value: &mut [f64],
    ) -> SampleResult {
        let nc = channels.count();
        value[..nc].fill(0.0);
        let s = strategy.sample_mapped(rnd, round);
        if !(s.pdf > 0.0) {
            return SampleResult::failed();
        }
        if s.coherent {
            match channels {
                Channels::Rgb => value[..3].copy_from_slice(&self.coherent_rgb(wi)),
                Channels::Wavelengths(lambdas) => {
                    for (v, &l) in value.iter_mut().zip(lambdas) {
                        *v = self.coherent_spectral(wi, l);
                    }
                }
            }
        } else {
            self.eval_channels(wi, s.wo, channels, value);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::benchmark::SplitMix64;

    fn materials() -> Vec<Brdf> {
        [
            r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":2.0,"fresnel":"gold"}"#,
            r#"{"surface":"gaussian","sigma_um":0.08,"corr_x_um":2,"corr_y_um":10}"#,
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1.0}"#,
            r#"{"surface":"cd","fresnel":"aluminium"}"#,
        ]
        .iter()
        .map(|j| Brdf::from_json(j).unwrap())
        .collect()
    }

    /// The vertex queries agree with the per-wavelength and per-query
    /// functions they stand for (the mixture of include/stam.h).
    #[test]
    fn vertex_queries_match_separate_queries() {
        let mut rng = SplitMix64(5);
        for brdf in materials() {
            for _ in 0..200 {
                let wi = DVec3::new(
                    rng.next_f64() - 0.5,
                    rng.next_f64() - 0.5,
                    0.1 + rng.next_f64(),
                )
                .normalize();
                let wo = DVec3::new(rng.next_f64() - 0.5, rng.next_f64() - 0.5, rng.next_f64())
                    .normalize();
                let lambdas = [380.0 + 400.0 * rng.next_f64(), 450.0, 560.0, 700.0];
                let channels = Channels::Wavelengths(&lambdas);
                let mut f = [0.0; 4];
                brdf.eval_channels(wi, wo, channels, &mut f);
                for (j, &l) in lambdas.iter().enumerate() {
                    assert_eq!(f[j], brdf.eval_spectral(wi, wo, l));
                }
                let mean: f64 = lambdas
                    .iter()
                    .map(|&l| brdf.pdf(wi, wo, Some(l)))
                    .sum::<f64>()
                    / 4.0;
                let pdf = brdf.pdf_channels(wi, wo, channels);
                assert!((pdf - mean).abs() <= 1e-12 * mean, "{pdf} {mean}");
                let mut rgb = [0.0; 3];
                brdf.eval_channels(wi, wo, Channels::Rgb, &mut rgb);
                assert_eq!(rgb, brdf.eval_rgb(wi, wo));
                assert_eq!(
                    brdf.pdf_channels(wi, wo, Channels::Rgb),
                    brdf.pdf(wi, wo, None)
                );

                // A sample's pdf and value are those of the queries at its wo.
                let rnd = rng.three();
                for ch in [channels, Channels::Rgb] {
                    let mut value = [0.0; 4];
                    let s = brdf.sample_channels(wi, ch, rnd, |w| w, &mut value);
                    if s.pdf == 0.0 {
                        assert!(value.iter().all(|&v| v == 0.0));
                        continue;
                    }
                    if s.coherent {
                        assert_eq!(s.pdf, brdf.coherent_probability_channels(wi, ch));
                        continue;
                    }
                    let p = brdf.pdf_channels(wi, s.wo, ch);
                    assert!((s.pdf - p).abs() <= 1e-12 * p, "{} {p}", s.pdf);
                    let mut f = [0.0; 4];
                    brdf.eval_channels(wi, s.wo, ch, &mut f);
                    assert_eq!(value, f);
                }
            }
        }
    }

    /// Hostile inputs: no channels, NaN, lambda = 0, below the horizon.
    #[test]
    fn vertex_queries_stay_finite() {
        for brdf in materials() {
            for (wi, lambdas) in [
                (DVec3::new(0.0, 0.0, 1.0), vec![]),
                (DVec3::new(0.3, 0.1, 0.9), vec![0.0, f64::NAN, 550.0, -1.0]),
                (DVec3::new(0.3, 0.1, -0.9), vec![550.0]),
                (DVec3::new(f64::NAN, 0.1, 0.9), vec![550.0, 600.0]),
            ] {
                let ch = Channels::Wavelengths(&lambdas);
                let mut v = [0.0; 4];
                for rnd in [[0.0, 0.0, 0.0], [0.999, 0.5, 0.5], [f64::NAN, 2.0, -1.0]] {
                    let s = brdf.sample_channels(wi, ch, rnd, |w| w, &mut v);
                    assert!(s.pdf.is_finite() && s.pdf >= 0.0);
                    assert!(v.iter().all(|x| x.is_finite() && *x >= 0.0));
                }
                let p = brdf.pdf_channels(wi, DVec3::new(0.1, 0.2, 0.9), ch);
                assert!(p.is_finite() && p >= 0.0);
            }
        }
    }
}
