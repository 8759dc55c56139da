//! What a surface model exports for a tracing renderer: its part of the
//! material's programs (crate::program, docs/jit.md). Each model implements
//! `SurfacePrograms` in its folder (`program.rs`), beside its physics, and
//! its tests run the programs against its native path. A method left at
//! its default (None) means the model has no such program: the material
//! then exports none of that kind, and the renderer says so.

use super::Shading;
use crate::optics::program::{PairProgram, Vec3};
use crate::program::{Builder, Mask, Value};

/// A sampled direction (a unit vector; anything below the horizon is a
/// failed sample) and whether it is the coherent lobe's mirror direction.
pub struct SampleProgram<'a> {
    pub wo: Vec3<'a>,
    pub coherent: Mask<'a>,
}

/// A factor of the pair's f per wavelength (the energy scaling of a
/// material whose table is per wavelength), which the RGB programs apply
/// inside their wavelength integration, where the native path applies
/// `Shading::pair_factor`.
pub trait FactorProgram<'a> {
    /// At a wavelength (nm) the program computes.
    fn at(&self, lambda_nm: Value<'a>) -> Value<'a>;
    /// At a fixed wavelength (nm), such as a rule's node (cheaper).
    fn at_nm(&self, lambda_nm: f64) -> Value<'a>;
}

/// Makes a pair's `FactorProgram` where a model first needs it, so that a
/// model that skips lanes (`Builder::region`) computes the factor only on
/// the lanes it does not skip.
pub type FactorMaker<'f, 'a> = &'f dyn Fn() -> Box<dyn FactorProgram<'a> + 'a>;

/// A model's programs. Directions are unit vectors above the horizon (the
/// material checks them and zeroes its outputs elsewhere); wavelengths are
/// inside the band where a model's output matters (outside it the material
/// zeroes f). `lambda_nm` None is the RGB mode.
pub trait SurfacePrograms {
    /// K at wavenumber k (1/um): f = F^2 G K.
    fn kernel_program<'a>(
        &self,
        _b: &'a Builder,
        _pair: &PairProgram<'a>,
        _k_per_um: Value<'a>,
    ) -> Option<Value<'a>> {
        None
    }

    /// `kernel_program` with the wavelength k was taken from (in-band, nm):
    /// the material calls this one. k in f32 carries the rounding of its
    /// division (6e-8), which moves a grating's narrow peaks by a visible
    /// fraction of their width at high orders; a model whose kernel needs
    /// the exact input wavelength overrides this, the others keep
    /// `kernel_program`.
    fn kernel_program_at<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
        _lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        self.kernel_program(b, pair, k_per_um)
    }

    /// Whether a model with its own f has programs (`unfactored_spectral_program`
    /// and its sampling); models whose f factors keep false.
    fn unfactored_programs(&self) -> bool {
        false
    }

    /// f itself at wavenumber k (from the in-band `lambda_nm`) for a model
    /// with its own f (`SurfaceModel::unfactored_spectral`: no Fresnel, G
    /// or energy factor); None where it has no program.
    fn unfactored_spectral_program<'a>(
        &self,
        _b: &'a Builder,
        _pair: &PairProgram<'a>,
        _k_per_um: Value<'a>,
        _lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        None
    }

    /// `unfactored_rgb`: f itself in linear sRGB, before gamut mapping;
    /// None where the model has no program.
    fn unfactored_rgb_program<'a>(
        &self,
        _b: &'a Builder,
        _pair: &PairProgram<'a>,
    ) -> Option<[Value<'a>; 3]> {
        None
    }

    /// `reflectance_rgb`: F^2 K integrated against the linear sRGB
    /// matching functions (f / G), before gamut mapping; with `factor`
    /// (the material's per-wavelength energy scaling, made by `factor`)
    /// F^2 K factor. A model that cannot take a factor returns None when
    /// given one (the material gives one only for tables per wavelength:
    /// the periodic model's).
    fn reflectance_rgb_program<'a>(
        &self,
        _b: &'a Builder,
        _shading: &Shading,
        _pair: &PairProgram<'a>,
        _factor: Option<FactorMaker<'_, 'a>>,
    ) -> Option<[Value<'a>; 3]> {
        None
    }

    /// The coherent lobe's reflectance at incidence cosine cos_i (in-band
    /// lambda), as `coherent_spectral`; models without one keep 0.
    fn coherent_spectral_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        _cos_i: Value<'a>,
        _lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        Some(b.c(0.0))
    }

    /// `coherent_rgb`, before gamut mapping; `factor` as in
    /// `reflectance_rgb_program` (at the mirror pair). Models without a
    /// coherent lobe keep 0, whatever the factor.
    fn coherent_rgb_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        _cos_i: Value<'a>,
        _factor: Option<&dyn FactorProgram<'a>>,
    ) -> Option<[Value<'a>; 3]> {
        Some([b.c(0.0); 3])
    }

    /// The probability that sampling at wi picks the coherent lobe.
    fn coherent_probability_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        _wi: Vec3<'a>,
        _lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        Some(b.c(0.0))
    }

    /// One sample at wi from three uniforms; the glossy part must have
    /// the density `pdf_program` gives.
    fn sample_program<'a>(
        &self,
        _b: &'a Builder,
        _shading: &Shading,
        _wi: Vec3<'a>,
        _lambda_nm: Option<Value<'a>>,
        _u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        None
    }

    /// The solid-angle density of `sample_program`'s glossy samples at wo
    /// (that is, already times 1 - the coherent probability).
    fn pdf_program<'a>(
        &self,
        _b: &'a Builder,
        _shading: &Shading,
        _wi: Vec3<'a>,
        _wo: Vec3<'a>,
        _lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        None
    }
}
