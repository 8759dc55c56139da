//! The material's programs for tracing renderers (crate::program,
//! docs/jit.md): what the plugin executes with Dr.Jit in the JIT variants.
//! The material does here what it does natively (checks the directions,
//! takes the pair geometry, G and Fresnel, gamut-maps RGB, zeroes bad
//! values) and asks its surface model (`models::SurfacePrograms`) for the
//! rest. Every kind has fixed inputs and outputs, listed in stam.h
//! (STAM_PROGRAM_*), the plugin's executor reads them in that order.

use super::energy::TableDerivative;
use super::Brdf;
use crate::models::{FactorMaker, FactorProgram};
use crate::optics::program::{upper_direction, PairProgram, Vec3};
use crate::program::{Builder, Mask, Program, Value};
use crate::sampling::program::{cosine_density_program, cosine_direction_program};
use crate::spectrum::{gamut_map_program, LAMBDA_MAX_NM, LAMBDA_MIN_NM};
use std::f64::consts::PI;

/// The kinds of program a material exports (mirror STAM_PROGRAM_* in
/// stam.h). Inputs / outputs:
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgramKind {
    /// wi (3), wo (3) -> f as R, G, B (without cos and the coherent lobe).
    EvalRgb = 0,
    /// wi (3), wo (3), lambda (nm) -> f.
    EvalSpectral = 1,
    /// wi (3), wo (3) -> the RGB strategy's glossy density at wo.
    PdfRgb = 2,
    /// wi (3), wo (3), lambda -> the one-wavelength strategy's density.
    PdfSpectral = 3,
    /// wi (3), u (3 uniforms) -> wo (3), coherent (1 or 0).
    SampleRgb = 4,
    /// wi (3), u (3), lambda -> wo (3), coherent.
    SampleSpectral = 5,
    /// wi (3) -> the coherent lobe's R, G, B, its sampling probability.
    CoherentRgb = 6,
    /// wi (3), lambda -> the coherent lobe's reflectance, its probability.
    CoherentSpectral = 7,
}

impl ProgramKind {
    pub const ALL: [ProgramKind; 8] = [
        ProgramKind::EvalRgb,
        ProgramKind::EvalSpectral,
        ProgramKind::PdfRgb,
        ProgramKind::PdfSpectral,
        ProgramKind::SampleRgb,
        ProgramKind::SampleSpectral,
        ProgramKind::CoherentRgb,
        ProgramKind::CoherentSpectral,
    ];

    pub fn from_code(code: u32) -> Option<ProgramKind> {
        Self::ALL.get(code as usize).copied()
    }

    /// Added to a kind's code (STAM_PROGRAM_AT_BUILT): the program for a
    /// renderer that passes every parameter at its built value
    /// (`Brdf::program_at_built`).
    pub const AT_BUILT: u32 = 256;

    /// Whether the kind takes a wavelength (its last input).
    pub fn spectral(self) -> bool {
        (self as u32) % 2 == 1
    }
}

fn input3(b: &Builder) -> Vec3<'_> {
    [b.input(), b.input(), b.input()]
}

/// lambda where it is inside the band (else 550, with the mask false).
fn band<'a>(lambda: Value<'a>) -> (Value<'a>, Mask<'a>) {
    let ok = lambda.ge(LAMBDA_MIN_NM) & lambda.le(LAMBDA_MAX_NM);
    (ok.select(lambda, 550.0), ok)
}

impl Brdf {
    /// The program of `kind`; None where the material has none (a model
    /// without that program). The energy scaling of "energy":
    /// "conserving" multiplies f where it does natively: a colour-neutral
    /// table's one factor outside the model's RGB, a table per wavelength
    /// (gratings) inside it (`FactorProgram`, at each wavelength the
    /// model's RGB integration takes).
    pub fn program(&self, kind: ProgramKind) -> Option<Program> {
        self.program_with(kind, self.plain_builder(), true)
    }

    /// The builder of the plain programs: for any parameter value, smooth
    /// along the parameters the renderer differentiates.
    fn plain_builder(&self) -> Builder {
        Builder::new().differentiating(&self.gradients)
    }

    /// The program of `kind` for a renderer that runs it only with every
    /// parameter at the value it was built with (no texture, no gradient,
    /// no update since): it may leave out what follows a parameter's
    /// change (the Gaussian folded RGB table's derivative channels, 48 of
    /// its 112 gathers; the energy table's derivatives). None where it
    /// would equal `program`'s.
    pub fn program_at_built(&self, kind: ProgramKind) -> Option<Program> {
        let lean = self.program_with(kind, Builder::at_built_values(), true)?;
        let plain = self.program(kind)?;
        (lean.encode() != plain.encode()).then_some(lean)
    }

    /// The program of `kind` from `b`; without `with_energy`, Stam's f even
    /// for a conserving material (what tells which parameters the model's
    /// own part reads).
    fn program_with(&self, kind: ProgramKind, b: Builder, with_energy: bool) -> Option<Program> {
        // A model with its own f (rigorous gratings) has no programs yet:
        // the JIT variants refuse it, the scalar ones render it.
        if self.surface.is_unfactored() {
            return None;
        }
        // Only the reflectance kinds scale by the energy table (sampling
        // and pdf follow Stam's strategy): the others build no table program
        // and no derivatives.
        let scales = matches!(
            kind,
            ProgramKind::EvalRgb
                | ProgramKind::EvalSpectral
                | ProgramKind::CoherentRgb
                | ProgramKind::CoherentSpectral
        );
        let energy = self.energy_table().filter(|_| with_energy && scales);
        let derivatives = match energy {
            Some(_) if !b.at_built() => self.derivatives_read_by(kind),
            _ => Vec::new(),
        };
        let energy = energy.map(|e| e.program(&b, &derivatives));
        let energy = energy.as_ref();
        let per_wavelength = energy.filter(|e| !e.colour_neutral());
        let model = self.surface.programs();
        let shading = self.shading();
        let outputs: Vec<Value> = match kind {
            ProgramKind::EvalRgb | ProgramKind::EvalSpectral => {
                let (wi, wo) = (input3(&b), input3(&b));
                let pair = PairProgram::new(&b, wi, wo);
                if kind == ProgramKind::EvalRgb {
                    let factor = per_wavelength.map(|e| {
                        move || Box::new(e.pair_factor(pair.wi, pair.wo)) as Box<dyn FactorProgram>
                    });
                    let rgb = model.reflectance_rgb_program(
                        &b,
                        &shading,
                        &pair,
                        factor.as_ref().map(|f| f as FactorMaker),
                    )?;
                    // A colour-neutral factor commutes with the gamut map.
                    let scale = match energy.filter(|e| e.colour_neutral()) {
                        Some(e) => pair.geometric_factor * e.pair(pair.wi, pair.wo, None)?,
                        None => pair.geometric_factor,
                    };
                    let rgb = gamut_map_program(rgb.map(|c| c * scale));
                    rgb.map(|c| pair.valid.select(c.finite_non_negative(), 0.0))
                        .to_vec()
                } else {
                    let (lambda, in_band) = band(b.input());
                    let k = (2000.0 * PI) / lambda;
                    let kernel = model.kernel_program_at(&b, &pair, k, lambda)?;
                    let f2 = self.fresnel.program(&b, pair.cos_half, lambda);
                    let mut f = f2 * pair.geometric_factor * kernel;
                    if let Some(e) = energy {
                        f = f * e.pair(pair.wi, pair.wo, Some(lambda))?;
                    }
                    let f = f.finite_non_negative();
                    vec![(pair.valid & in_band).select(f, 0.0)]
                }
            }
            ProgramKind::PdfRgb | ProgramKind::PdfSpectral => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let (wo, ok_o) = upper_direction(&b, input3(&b));
                let lambda = kind.spectral().then(|| band(b.input()).0);
                let pdf = match model.pdf_program(&b, &shading, wi, wo, lambda) {
                    Some(p) => p,
                    None => {
                        let p_c = model.coherent_probability_program(&b, &shading, wi, lambda)?;
                        (1.0 - p_c) * cosine_density_program(wo)
                    }
                };
                vec![(ok_i & ok_o).select(pdf.finite_non_negative(), 0.0)]
            }
            ProgramKind::SampleRgb | ProgramKind::SampleSpectral => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let u = [b.input(), b.input(), b.input()];
                let lambda = kind.spectral().then(|| band(b.input()).0);
                let s = match model.sample_program(&b, &shading, wi, lambda, u) {
                    Some(s) => s,
                    None => {
                        let p_c = model.coherent_probability_program(&b, &shading, wi, lambda)?;
                        let coherent = u[0].lt(p_c);
                        let glossy = cosine_direction_program(&b, u[1], u[2]);
                        let mirror = [-wi[0], -wi[1], wi[2]];
                        crate::models::SampleProgram {
                            wo: std::array::from_fn(|j| coherent.select(mirror[j], glossy[j])),
                            coherent,
                        }
                    }
                };
                // A failed sample: below the horizon, not coherent.
                let wo = s.wo.map(|c| ok_i.select(c, 0.0));
                let wo = [wo[0], wo[1], ok_i.select(wo[2], -1.0)];
                let coherent = (s.coherent & ok_i).select(1.0, 0.0);
                vec![wo[0], wo[1], wo[2], coherent]
            }
            ProgramKind::CoherentRgb | ProgramKind::CoherentSpectral => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let mirror = [-wi[0], -wi[1], wi[2]];
                let (rgb, lambda, ok) = if kind == ProgramKind::CoherentRgb {
                    let factor = per_wavelength.map(|e| e.pair_factor(wi, mirror));
                    let mut rgb = model.coherent_rgb_program(
                        &b,
                        &shading,
                        wi[2],
                        factor.as_ref().map(|f| f as &dyn FactorProgram),
                    )?;
                    if let Some(e) = energy.filter(|e| e.colour_neutral()) {
                        let m = e.pair(wi, mirror, None)?;
                        rgb = rgb.map(|c| c * m);
                    }
                    (gamut_map_program(rgb).to_vec(), None, ok_i)
                } else {
                    let (lambda, in_band) = band(b.input());
                    let mut r = model.coherent_spectral_program(&b, &shading, wi[2], lambda)?;
                    if let Some(e) = energy {
                        r = r * e.pair(wi, mirror, Some(lambda))?;
                    }
                    (vec![r], Some(lambda), ok_i & in_band)
                };
                let p_c = model.coherent_probability_program(&b, &shading, wi, lambda)?;
                let mut out: Vec<Value> = rgb
                    .into_iter()
                    .map(|c| ok.select(c.finite_non_negative(), 0.0))
                    .collect();
                out.push(ok_i.select(p_c.finite_non_negative().min(1.0), 0.0));
                out
            }
        };
        Some(b.finish(&outputs))
    }

    /// The energy table's derivatives along the parameters that the
    /// model's own part of the program of `kind` reads (a model's program
    /// that held a parameter constant would get half a gradient along it).
    fn derivatives_read_by(&self, kind: ProgramKind) -> Vec<&TableDerivative> {
        let all = self.energy_derivatives();
        if all.is_empty() {
            return Vec::new();
        }
        let Some(stam) = self.program_with(kind, self.plain_builder(), false) else {
            return Vec::new();
        };
        all.iter()
            .filter(|d| stam.param_slot(d.id).is_some())
            .collect()
    }
}
