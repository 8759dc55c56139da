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
use crate::spectrum::{gamut_map_program, wavenumber_per_um, LAMBDA_MAX_NM, LAMBDA_MIN_NM};

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

    /// The kind's (inputs, outputs): the table above (stam_program_io).
    pub fn io(self) -> (usize, usize) {
        let lambda = self.spectral() as usize;
        match self {
            ProgramKind::EvalRgb => (6, 3),
            ProgramKind::EvalSpectral | ProgramKind::PdfRgb | ProgramKind::PdfSpectral => {
                (6 + lambda, 1)
            }
            ProgramKind::SampleRgb | ProgramKind::SampleSpectral => (6 + lambda, 4),
            ProgramKind::CoherentRgb => (3, 4),
            ProgramKind::CoherentSpectral => (4, 2),
        }
    }
}

/// The programs of a spectral renderer's one-sample mixture over the N
/// wavelengths a path carries (the native `Brdf::mixture_sampler`): each
/// wavelength's strategy (the spectral kinds') an equally weighted
/// component. Exported for any N in 1..=MAX_MIXTURE_WAVELENGTHS
/// (`Brdf::mixture_program`; STAM_MIXTURE_* in stam.h), so that a host
/// holds no mixture rule. Inputs / outputs:
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MixtureKind {
    /// wi (3), wo (3), lambda (N) -> the mixture's glossy density at wo
    /// (the mean of the wavelengths' PdfSpectral).
    Pdf = 0,
    /// wi (3), u (3), lambda (N) -> wo (3), coherent: u0 picks wavelength
    /// j = floor(N u0) and, remapped to N u0 - j, samples with u1, u2 as
    /// SampleSpectral at lambda_j.
    Sample = 1,
    /// wi (3), lambda (N) -> each wavelength's coherent reflectance (N),
    /// the mixture's coherent probability (the mean of the wavelengths').
    Coherent = 2,
}

/// The most wavelengths a mixture program takes.
pub const MAX_MIXTURE_WAVELENGTHS: usize = 16;

impl MixtureKind {
    pub const ALL: [MixtureKind; 3] =
        [MixtureKind::Pdf, MixtureKind::Sample, MixtureKind::Coherent];

    pub fn from_code(code: u32) -> Option<MixtureKind> {
        Self::ALL.get(code as usize).copied()
    }

    /// The kind's (inputs, outputs) for n wavelengths.
    pub fn io(self, n: usize) -> (usize, usize) {
        match self {
            MixtureKind::Pdf => (6 + n, 1),
            MixtureKind::Sample => (6 + n, 4),
            MixtureKind::Coherent => (3 + n, n + 1),
        }
    }
}

/// A probability as an output: in [0, 1] where `ok`, else 0.
fn probability<'a>(ok: Mask<'a>, p: Value<'a>) -> Value<'a> {
    ok.select(p.finite_non_negative().min(1.0), 0.0)
}

/// The largest f32 below 1: where a remapped uniform is clamped.
const ONE_MINUS_F32: f64 = 1.0 - 1.0 / 16_777_216.0;

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

    /// The polarisation's program (`stam_brdf_export_polarization_program`):
    /// wi (3), wo (3), lambda (nm) -> b, c, s of `Brdf::polarization`, the
    /// Fresnel reflection's at the pair's half vector (normal incidence's
    /// for a pair below the horizon). None where `polarization` is None
    /// (rigorous gratings).
    pub fn polarization_program(&self) -> Option<Program> {
        if !self.polarizes() {
            return None;
        }
        let b = self.plain_builder();
        let wi = [b.input(), b.input(), b.input()];
        let wo = [b.input(), b.input(), b.input()];
        let lambda_nm = b.input();
        let pair = PairProgram::new(&b, wi, wo);
        let out = self
            .fresnel()
            .polarization_program(&b, pair.cos_half, lambda_nm);
        Some(b.finish(&out))
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
        // A model with its own f (rigorous gratings): f is the model's,
        // with no Fresnel, G or energy factor, where the model has programs.
        let unfactored = self.surface.is_unfactored();
        if unfactored && !self.surface.programs().unfactored_programs() {
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
        let energy = (with_energy && scales)
            .then(|| self.energy_program(&b, kind))
            .flatten();
        let energy = energy.as_ref();
        let per_wavelength = energy.filter(|e| !e.colour_neutral());
        let model = self.surface.programs();
        let shading = self.shading();
        let outputs: Vec<Value> = match kind {
            ProgramKind::EvalRgb | ProgramKind::EvalSpectral => {
                let (wi, wo) = (input3(&b), input3(&b));
                let pair = PairProgram::new(&b, wi, wo);
                if kind == ProgramKind::EvalRgb && unfactored {
                    let rgb = gamut_map_program(model.unfactored_rgb_program(&b, &pair)?);
                    rgb.map(|c| pair.valid.select(c.finite_non_negative(), 0.0))
                        .to_vec()
                } else if kind == ProgramKind::EvalRgb {
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
                    let k = wavenumber_per_um(lambda);
                    if unfactored {
                        let f = model.unfactored_spectral_program(&b, &pair, k, lambda)?;
                        return Some(b.finish(&[(pair.valid & in_band).select(f, 0.0)]));
                    }
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
                let pdf = self.glossy_pdf(&b, wi, wo, lambda)?;
                vec![(ok_i & ok_o).select(pdf.finite_non_negative(), 0.0)]
            }
            ProgramKind::SampleRgb | ProgramKind::SampleSpectral => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let u = [b.input(), b.input(), b.input()];
                let lambda = kind.spectral().then(|| band(b.input()).0);
                self.sample_outputs(&b, wi, ok_i, lambda, u)?
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
                    let r = self.coherent_reflectance(&b, energy, wi, mirror, lambda)?;
                    (vec![r], Some(lambda), ok_i & in_band)
                };
                let p_c = self.coherent_probability_of(&b, wi, lambda)?;
                let mut out: Vec<Value> = rgb
                    .into_iter()
                    .map(|c| ok.select(c.finite_non_negative(), 0.0))
                    .collect();
                out.push(probability(ok_i, p_c));
                out
            }
        };
        Some(b.finish(&outputs))
    }

    /// The strategy's glossy density at wo (unit wi, wo above the horizon;
    /// lambda None: RGB), as `Brdf::pdf`: the model's, or the cosine part
    /// of a model without a density of its own.
    fn glossy_pdf<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let model = self.surface.programs();
        let shading = self.shading();
        match model.pdf_program(b, &shading, wi, wo, lambda) {
            Some(p) => Some(p),
            None => {
                let p_c = model.coherent_probability_program(b, &shading, wi, lambda)?;
                Some((1.0 - p_c) * cosine_density_program(wo))
            }
        }
    }

    /// A sample's outputs (wo, coherent as 1 or 0) at wi (`ok_i`: above the
    /// horizon) from uniforms `u`, as `Brdf::sample`; a failed sample points
    /// below the horizon.
    fn sample_outputs<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        ok_i: Mask<'a>,
        lambda: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<Vec<Value<'a>>> {
        let model = self.surface.programs();
        let shading = self.shading();
        let s = match model.sample_program(b, &shading, wi, lambda, u) {
            Some(s) => s,
            None => {
                let p_c = model.coherent_probability_program(b, &shading, wi, lambda)?;
                let coherent = u[0].lt(p_c);
                let glossy = cosine_direction_program(b, u[1], u[2]);
                let mirror = [-wi[0], -wi[1], wi[2]];
                crate::models::SampleProgram {
                    wo: std::array::from_fn(|j| coherent.select(mirror[j], glossy[j])),
                    coherent,
                }
            }
        };
        let wo = s.wo.map(|c| ok_i.select(c, 0.0));
        let wo = [wo[0], wo[1], ok_i.select(wo[2], -1.0)];
        let coherent = (s.coherent & ok_i).select(1.0, 0.0);
        Some(vec![wo[0], wo[1], wo[2], coherent])
    }

    /// The coherent lobe's reflectance at wi (its mirror direction
    /// `mirror`) and an in-band wavelength, scaled by the energy table
    /// where the material has one.
    fn coherent_reflectance<'a>(
        &self,
        b: &'a Builder,
        energy: Option<&super::energy::TableProgram<'a>>,
        wi: Vec3<'a>,
        mirror: Vec3<'a>,
        lambda: Value<'a>,
    ) -> Option<Value<'a>> {
        let model = self.surface.programs();
        let mut r = model.coherent_spectral_program(b, &self.shading(), wi[2], lambda)?;
        if let Some(e) = energy {
            r = r * e.pair(wi, mirror, Some(lambda))?;
        }
        Some(r)
    }

    /// The probability that sampling at wi picks the coherent lobe (the
    /// model's, before `probability`).
    fn coherent_probability_of<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        lambda: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let model = self.surface.programs();
        model.coherent_probability_program(b, &self.shading(), wi, lambda)
    }

    /// The mixture program of `kind` over `n` wavelengths (1..=
    /// MAX_MIXTURE_WAVELENGTHS); None where the material has no spectral
    /// programs or n is out of range.
    pub fn mixture_program(&self, kind: MixtureKind, n: usize) -> Option<Program> {
        self.mixture_program_with(kind, n, self.plain_builder())
    }

    /// `mixture_program` for a renderer that passes every parameter at its
    /// built value (`program_at_built`); None where it would be the same.
    pub fn mixture_program_at_built(&self, kind: MixtureKind, n: usize) -> Option<Program> {
        let lean = self.mixture_program_with(kind, n, Builder::at_built_values())?;
        let plain = self.mixture_program(kind, n)?;
        (lean.encode() != plain.encode()).then_some(lean)
    }

    fn mixture_program_with(&self, kind: MixtureKind, n: usize, b: Builder) -> Option<Program> {
        let unfactored = self.surface.is_unfactored();
        if (unfactored && !self.surface.programs().unfactored_programs())
            || !(1..=MAX_MIXTURE_WAVELENGTHS).contains(&n)
        {
            return None;
        }
        let scale = 1.0 / n as f64;
        let outputs = match kind {
            MixtureKind::Pdf => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let (wo, ok_o) = upper_direction(&b, input3(&b));
                let lambdas: Vec<Value> = (0..n).map(|_| band(b.input()).0).collect();
                let mut sum = b.c(0.0);
                for lambda in lambdas {
                    sum = sum
                        + self
                            .glossy_pdf(&b, wi, wo, Some(lambda))?
                            .finite_non_negative();
                }
                vec![(ok_i & ok_o).select(sum * scale, 0.0)]
            }
            MixtureKind::Sample => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let u = [b.input(), b.input(), b.input()];
                let lambdas: Vec<Value> = (0..n).map(|_| b.input()).collect();
                // u0 picks the component and, remapped, goes on to it.
                let u0 = u[0].finite().select(u[0], 0.0);
                let x = u0 * n as f64;
                let j = x.floor().clamp(0.0, (n - 1) as f64);
                let u0 = (x - j).clamp(0.0, ONE_MINUS_F32);
                let mut lambda = lambdas[0];
                for (k, &l) in lambdas.iter().enumerate().skip(1) {
                    lambda = j.eq(k as f64).select(l, lambda);
                }
                let lambda = band(lambda).0;
                self.sample_outputs(&b, wi, ok_i, Some(lambda), [u0, u[1], u[2]])?
            }
            MixtureKind::Coherent => {
                let (wi, ok_i) = upper_direction(&b, input3(&b));
                let mirror = [-wi[0], -wi[1], wi[2]];
                let lambdas: Vec<Value> = (0..n).map(|_| b.input()).collect();
                let energy = self.energy_program(&b, ProgramKind::CoherentSpectral);
                let mut out = Vec::with_capacity(n + 1);
                let mut p_sum = b.c(0.0);
                for raw in lambdas {
                    let (lambda, in_band) = band(raw);
                    let r = self.coherent_reflectance(&b, energy.as_ref(), wi, mirror, lambda)?;
                    let p_c = self.coherent_probability_of(&b, wi, Some(lambda))?;
                    out.push((ok_i & in_band).select(r.finite_non_negative(), 0.0));
                    p_sum = p_sum + probability(ok_i, p_c);
                }
                out.push(p_sum * scale);
                out
            }
        };
        Some(b.finish(&outputs))
    }

    /// The energy table in the program of `kind` (None without one), with
    /// its derivatives along the parameters the model's part of that kind
    /// reads (none for a program run at the built parameters).
    fn energy_program<'a>(
        &'a self,
        b: &'a Builder,
        kind: ProgramKind,
    ) -> Option<super::energy::TableProgram<'a>> {
        let table = self.energy_table()?;
        let derivatives = match b.at_built() {
            true => Vec::new(),
            false => self.derivatives_read_by(kind),
        };
        Some(table.program(b, &derivatives))
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
