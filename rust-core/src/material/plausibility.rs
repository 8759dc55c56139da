//! Plausibility of accepted parameters: warnings where a value is almost
//! surely a unit mistake or makes the model degenerate (no diffraction
//! effect left, or the model outside the physics it rests on). Invalid
//! values are refused by the parameter readers; what is merely implausible
//! is accepted and reported here, so that renderers can log it (the
//! Mitsuba plugin logs each warning once per material; `stam_brdf_warnings`
//! in stam.h).
//!
//! The rules, with k = 2 pi / lambda and w = 2 (normal incidence, mirror
//! direction), the geometry where each quantity is largest:
//! - Gaussian: g = (k sigma w)^2 at 700 nm at least `BECKMANN_G` = 1e4 (from
//!   sigma = 5.6 um): the Beckmann limit everywhere but within a degree of
//!   grazing, a colourless rough metal; g at 400 nm below `MIRROR_G` = 1e-4:
//!   a perfect mirror; the diffuse lobe's angular half-width 2 sqrt(max(1, g))
//!   / (k T) at 550 nm narrower than `NARROW_LOBE` = 1 mrad (a mirror for any
//!   real light) or wider than the hemisphere (2: slopes beyond 45 degrees
//!   or correlation length below lambda / 2 pi, outside the Kirchhoff
//!   approximation).
//! - Fractal: the lobe's half-width a^(1/2H) / k at 550 nm, a = k^2 w^2
//!   sigma^2 / (2 lag^2H) (docs/physics.md), narrower than 1 mrad or wider
//!   than the hemisphere.
//! - Periodic: a period below 0.2 um (no order but the mirror one leaves the
//!   surface at any visible wavelength) or above 100 um (the first order's
//!   rainbow spans under 3 mrad, less than a small lamp); a profile so flat
//!   that its phase k w h at 400 nm stays below 0.02 (the orders carry less
//!   than 1e-4 of the light) or deeper than the period (walls that shadow
//!   and reflect into each other, which the model leaves out).

use super::params::MaterialParams;
use crate::json::{nanometre_hint, show};
use crate::models::fractal::FractalParams;
use crate::models::gaussian::GaussianParams;
use crate::models::periodic::{PeriodicParams, Profile};
use crate::models::SurfaceParams;
use crate::spectrum::wavenumber_per_um;
use std::fmt;

/// g at 700 nm and normal incidence from which a Gaussian surface is
/// "far into the Beckmann limit".
pub const BECKMANN_G: f64 = 1e4;
/// g at 400 nm and normal incidence below which a Gaussian surface is a mirror.
pub const MIRROR_G: f64 = 1e-4;
/// Lobe half-width (radians, direction cosines) below which a lobe is a mirror.
pub const NARROW_LOBE: f64 = 1e-3;
/// Lobe half-width (direction cosines) above which it is wider than the hemisphere.
pub const WIDE_LOBE: f64 = 2.0;
/// Periods outside which a grating shows no diffraction colours (um).
pub const PERIOD_UM: (f64, f64) = (0.2, 100.0);
/// Phase k w h_pp (400 nm, normal incidence) below which a profile is flat.
pub const FLAT_PHASE: f64 = 0.02;

/// One warning: the parameter it is about and a sentence for the user.
#[derive(Clone, Debug, PartialEq)]
pub struct Warning {
    pub key: &'static str,
    pub message: String,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

fn warn(out: &mut Vec<Warning>, key: &'static str, message: String) {
    out.push(Warning { key, message });
}

/// k at `lambda_nm` times w = 2 (normal incidence, mirror direction).
fn kw(lambda_nm: f64) -> f64 {
    2.0 * wavenumber_per_um(lambda_nm)
}

/// The warnings of a material's parameters, in the order of its keys.
pub fn warnings(params: &MaterialParams) -> Vec<Warning> {
    let mut out = Vec::new();
    match &params.surface {
        SurfaceParams::Gaussian(p) => gaussian(p, &mut out),
        SurfaceParams::Fractal(p) => fractal(p, &mut out),
        SurfaceParams::Periodic(p) => periodic(p, &mut out),
        SurfaceParams::HeightMap(p) => heightmap(p, &mut out),
    }
    out
}

/// The warnings of a JSON parameter object; none when it does not parse
/// (the parameter readers report that).
pub fn warnings_for_json(text: &str) -> Vec<Warning> {
    MaterialParams::from_json(text)
        .map(|p| warnings(&p))
        .unwrap_or_default()
}

/// A map's spectrum ends at its Nyquist frequency 1 / (2 pixel), that is
/// at |(u, v)| = lambda / (2 pixel): below lambda = 4 pixel, light
/// scattered further than that from the mirror is missing.
fn heightmap(p: &crate::models::heightmap::HeightMapParams, out: &mut Vec<Warning>) {
    let cut_nm = 4000.0 * p.pixel_um;
    if cut_nm > crate::spectrum::LAMBDA_MIN_NM {
        warn(
            out,
            "pixel_um",
            format!(
                "parameter 'pixel_um' = {} um is coarser than a quarter of the shortest wavelength: the map's spectrum ends at |(u, v)| = lambda / (2 pixel_um), below 2 for wavelengths under {} nm, so the light such a map scatters far from the mirror direction is missing there (a map sampled at 0.09 um or finer has all of it).",
                show(p.pixel_um),
                show(cut_nm.min(9999.0))
            ),
        );
    }
}

fn gaussian(p: &GaussianParams, out: &mut Vec<Warning>) {
    let sigma = p.sigma_um;
    let t_long = p.corr_x_um.max(p.corr_y_um);
    let t_short = p.corr_x_um.min(p.corr_y_um);
    let corr_key = if p.anisotropic {
        if p.corr_x_um >= p.corr_y_um {
            "corr_x_um"
        } else {
            "corr_y_um"
        }
    } else {
        "corr_um"
    };
    let short_key = match corr_key {
        "corr_x_um" => "corr_y_um",
        "corr_y_um" => "corr_x_um",
        k => k,
    };
    let g_red = (kw(700.0) * sigma).powi(2);
    let g_blue = (kw(400.0) * sigma).powi(2);
    if g_red >= BECKMANN_G {
        // g = g_red cos^2(theta) falls to 1 only within this angle of grazing.
        let grazing_deg = (1.0 / g_red.sqrt()).asin().to_degrees();
        warn(
            out,
            "sigma_um",
            format!(
                "parameter 'sigma_um' = {} um is far into the Beckmann limit: g = (2 k sigma cos theta)^2 = {} at normal incidence even at 700 nm, so no diffraction colour appears except within {} degrees of grazing; the surface renders as a colourless rough metal of Beckmann roughness alpha = 2 sigma / T = {} (Mitsuba's roughconductor does the same faster). Diffraction colours need g near 1: sigma of a few hundredths of a micrometre (e.g. sigma_um 0.03 with corr_um 1).{}",
                show(sigma),
                show(g_red),
                show(grazing_deg),
                show(2.0 * sigma / t_short),
                nanometre_hint("sigma_um", sigma)
            ),
        );
    } else if g_blue < MIRROR_G {
        warn(
            out,
            "sigma_um",
            format!(
                "parameter 'sigma_um' = {} um makes a perfect mirror: g = (2 k sigma cos theta)^2 < {} even at 400 nm, so less than 1e-4 of the light leaves the mirror direction; diffraction colours need sigma of a few hundredths of a micrometre (e.g. sigma_um 0.03 with corr_um 1).",
                show(sigma),
                show(MIRROR_G)
            ),
        );
    }
    // The diffuse lobe: term m of the series is exp(-k^2 T^2 |(u,v)|^2 / 4m),
    // and the terms that matter have m ~ max(1, g).
    let k = wavenumber_per_um(550.0);
    let g = (kw(550.0) * sigma).powi(2);
    let spread = 2.0 * g.max(1.0).sqrt() / k;
    let narrow = spread / t_long;
    let wide = spread / t_short;
    if g_red < BECKMANN_G && g_blue >= MIRROR_G && narrow < NARROW_LOBE {
        warn(
            out,
            corr_key,
            format!(
                "parameter '{corr_key}' = {} um makes the diffuse lobe {} mrad wide at 550 nm, narrower than any real light source: the surface renders as a mirror and its lobe is hard to sample. Visible diffraction colours need a correlation length of a few micrometres (e.g. corr_um 1 with sigma_um 0.03).{}",
                show(t_long),
                show(narrow * 1000.0),
                nanometre_hint(corr_key, t_long)
            ),
        );
    }
    if wide > WIDE_LOBE {
        warn(
            out,
            short_key,
            format!(
                "parameters 'sigma_um' = {} um and '{short_key}' = {} um make the diffuse lobe wider than the hemisphere (half-width {} in direction cosines at 550 nm): the slopes are steeper than 45 degrees (alpha = 2 sigma / T = {}) or the correlation length is below the wavelength, outside the Kirchhoff approximation the model rests on (no shadowing, masking or multiple scattering); the result is not physical.",
                show(sigma),
                show(t_short),
                show(wide),
                show(2.0 * sigma / t_short)
            ),
        );
    }
}

fn fractal(p: &FractalParams, out: &mut Vec<Warning>) {
    // a = k^2 w^2 s^2 / (2 L^2H); the lobe's scale in q = k (u, v) is a^(1/2H).
    let k = wavenumber_per_um(550.0);
    let a = (kw(550.0) * p.sigma_um).powi(2) / (2.0 * p.lag_um.powf(2.0 * p.hurst));
    let width = a.powf(1.0 / (2.0 * p.hurst)) / k;
    if !width.is_finite() || width > WIDE_LOBE {
        warn(
            out,
            "sigma_um",
            format!(
                "parameters 'sigma_um' = {} um, 'lag_um' = {} um and 'hurst' = {} make the lobe wider than the hemisphere (half-width {} in direction cosines at 550 nm): the slopes are steeper than 45 degrees, outside the Kirchhoff approximation the model rests on; the result is not physical.{}",
                show(p.sigma_um),
                show(p.lag_um),
                show(p.hurst),
                show(width),
                nanometre_hint("sigma_um", p.sigma_um)
            ),
        );
    } else if width < NARROW_LOBE {
        warn(
            out,
            "sigma_um",
            format!(
                "parameters 'sigma_um' = {} um, 'lag_um' = {} um and 'hurst' = {} make the lobe {} mrad wide at 550 nm, narrower than any real light source: the surface renders as a mirror and its lobe is hard to sample.",
                show(p.sigma_um),
                show(p.lag_um),
                show(p.hurst),
                show(width * 1000.0)
            ),
        );
    }
}

fn periodic(p: &PeriodicParams, out: &mut Vec<Warning>) {
    let period = p.period_um;
    if period < PERIOD_UM.0 {
        warn(
            out,
            "period_um",
            format!(
                "parameter 'period_um' = {} um is shorter than half the shortest visible wavelength ({} um): no diffraction order but the mirror one leaves the surface at any angle, so the grating shows no colours.",
                show(period),
                PERIOD_UM.0
            ),
        );
    } else if period > PERIOD_UM.1 {
        warn(
            out,
            "period_um",
            format!(
                "parameter 'period_um' = {} um spreads the first order's rainbow over only {} mrad (0.3 um / period), less than a small lamp subtends: the colours wash out. Compact discs have 1.6 um, DVDs 0.74 um, Blu-ray discs 0.32 um.{}",
                show(period),
                show(300.0 / period),
                nanometre_hint("period_um", period)
            ),
        );
    }
    let (key, depth) = match &p.profile {
        Profile::Rect { height_um, .. } | Profile::Sine { height_um } => ("height_um", *height_um),
        Profile::Tabulated { heights_um } => {
            let hi = heights_um.iter().cloned().fold(f64::MIN, f64::max);
            let lo = heights_um.iter().cloned().fold(f64::MAX, f64::min);
            ("profile", hi - lo)
        }
    };
    let what = if key == "profile" {
        "the profile's height range"
    } else {
        "the profile's height"
    };
    if kw(400.0) * depth < FLAT_PHASE {
        warn(
            out,
            key,
            format!(
                "parameter '{key}': {what} ({} um) is so small that the phase k w h stays below {FLAT_PHASE} even at 400 nm: the diffraction orders carry less than 1e-4 of the light and the surface renders as a mirror (a compact disc's pits are 0.1-0.15 um deep).",
                show(depth)
            ),
        );
    } else if depth > period {
        warn(
            out,
            key,
            format!(
                "parameter '{key}': {what} ({} um) exceeds the period ({} um): grooves deeper than they are wide shadow and reflect into each other, which the model leaves out; the result is not physical.",
                show(depth),
                show(period)
            ),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(json: &str) -> Vec<&'static str> {
        warnings_for_json(json).iter().map(|w| w.key).collect()
    }

    fn one(json: &str) -> Warning {
        let w = warnings_for_json(json);
        assert_eq!(w.len(), 1, "{json}: {w:?}");
        w.into_iter().next().unwrap()
    }

    /// The paper's materials and the project's scenes are plausible.
    #[test]
    fn plausible_materials_have_no_warnings() {
        for json in [
            r#"{"surface":"cd"}"#,
            r#"{"surface":"cd","period_um":1.6}"#,
            r#"{"surface":"cd","period_um":0.74,"height_um":0.12,"width_um":0.4}"#,
            r#"{"surface":"cd","period_um":0.32,"height_um":0.08,"width_um":0.15}"#,
            r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":1}"#,
            r#"{"surface":"gaussian","sigma_um":0.2,"corr_um":2,"fresnel":"gold"}"#,
            r#"{"surface":"gaussian","sigma_um":0.0055,"corr_um":4}"#,
            r#"{"surface":"gaussian","sigma_um":0.55,"corr_um":4}"#,
            r#"{"surface":"gaussian","sigma_um":2.0,"corr_um":10}"#,
            r#"{"surface":"gaussian","sigma_um":0.25,"corr_x_um":1.5,"corr_y_um":25}"#,
            r#"{"surface":"gaussian","sigma_um":0.3,"corr_x_um":3,"corr_y_um":300}"#,
            r#"{"surface":"fractal","sigma_um":0.05,"hurst":0.5,"lag_um":1}"#,
            r#"{"surface":"fractal","sigma_um":0.05,"hurst":0.7,"lag_um":1}"#,
            r#"{"surface":"periodic","period_um":3,"coherence_um":30,"profile":"sine","height_um":0.3}"#,
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":{"heights_um":[0,0.1,0.2,0.1]}}"#,
        ] {
            assert_eq!(warnings_for_json(json), vec![], "{json}");
        }
    }

    /// The unit mistakes of the issue: nanometres written as micrometres.
    #[test]
    fn nanometres_as_micrometres_are_reported() {
        let w = one(r#"{"surface":"gaussian","sigma_um":100,"corr_um":1000}"#);
        assert_eq!(w.key, "sigma_um");
        assert!(w.message.contains("'sigma_um' = 100 um"), "{w}");
        assert!(w.message.contains("Beckmann"), "{w}");
        assert!(w.message.contains("sigma_um = 0.1 (micrometres)"), "{w}");
        // With a short correlation length also steeper than 45 degrees
        let k = keys(r#"{"surface":"gaussian","sigma_um":100,"corr_um":2}"#);
        assert_eq!(k, vec!["sigma_um", "corr_um"]);

        let w = one(r#"{"surface":"gaussian","sigma_um":60,"corr_um":1000}"#);
        assert_eq!(w.key, "sigma_um");
        assert!(w.message.contains("alpha = 2 sigma / T = 0.12"), "{w}");

        let w = one(r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":1000}"#);
        assert_eq!(w.key, "corr_um");
        assert!(w.message.contains("corr_um = 1 (micrometres)"), "{w}");

        let w = one(r#"{"surface":"cd","period_um":740,"width_um":0.4}"#);
        assert_eq!(w.key, "period_um");
        assert!(w.message.contains("period_um = 0.74"), "{w}");
    }

    #[test]
    fn degenerate_models_are_reported() {
        let w = one(r#"{"surface":"gaussian","sigma_um":0.0001,"corr_um":2}"#);
        assert!(w.key == "sigma_um" && w.message.contains("mirror"), "{w}");
        // Correlation length below the wavelength
        let w = one(r#"{"surface":"gaussian","sigma_um":0.01,"corr_um":0.05}"#);
        assert!(
            w.key == "corr_um" && w.message.contains("hemisphere"),
            "{w}"
        );
        // Anisotropic: each key by its own length
        let k = keys(r#"{"surface":"gaussian","sigma_um":0.03,"corr_x_um":0.05,"corr_y_um":5000}"#);
        assert_eq!(k, vec!["corr_y_um", "corr_x_um"]);
        // Fractal: too rough, too smooth
        let w = one(r#"{"surface":"fractal","sigma_um":5,"hurst":0.5,"lag_um":1}"#);
        assert!(
            w.key == "sigma_um" && w.message.contains("hemisphere"),
            "{w}"
        );
        let w = one(r#"{"surface":"fractal","sigma_um":0.00001,"hurst":1,"lag_um":1}"#);
        assert!(w.key == "sigma_um" && w.message.contains("mirror"), "{w}");
        // Gratings: no orders, flat, too deep
        let w = one(r#"{"surface":"cd","period_um":0.1,"width_um":0.05,"height_um":0.05}"#);
        assert!(
            w.key == "period_um" && w.message.contains("no diffraction order"),
            "{w}"
        );
        let w = one(r#"{"surface":"cd","height_um":0.0001}"#);
        assert!(w.key == "height_um" && w.message.contains("mirror"), "{w}");
        let w = one(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":{"heights_um":[0,0.00001]}}"#,
        );
        assert!(
            w.key == "profile" && w.message.contains("height range"),
            "{w}"
        );
        let w = one(r#"{"surface":"cd","height_um":5}"#);
        assert!(w.key == "height_um" && w.message.contains("deeper"), "{w}");
    }

    /// Each rule's threshold: just inside stays silent, just outside warns.
    #[test]
    fn thresholds_are_where_the_rules_say() {
        let sigma_beckmann = BECKMANN_G.sqrt() / kw(700.0);
        let json = |s: f64| format!(r#"{{"surface":"gaussian","sigma_um":{s},"corr_um":100}}"#);
        assert_eq!(keys(&json(sigma_beckmann * 0.99)), Vec::<&str>::new());
        assert_eq!(keys(&json(sigma_beckmann * 1.01)), vec!["sigma_um"]);
        let cd = |p: f64| format!(r#"{{"surface":"cd","period_um":{p},"width_um":0.05}}"#);
        assert_eq!(keys(&cd(0.21)), Vec::<&str>::new());
        assert_eq!(keys(&cd(0.19)), vec!["period_um"]);
        assert_eq!(keys(&cd(99.0)), Vec::<&str>::new());
        assert_eq!(keys(&cd(101.0)), vec!["period_um"]);
    }

    #[test]
    fn unparsable_parameters_have_no_warnings() {
        assert!(warnings_for_json("not json").is_empty());
        assert!(warnings_for_json(r#"{"surface":"gaussian"}"#).is_empty());
    }
}
