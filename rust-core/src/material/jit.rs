//! The JIT export (prototype, docs/jit.md): what a renderer that traces its
//! BSDF code (Dr.Jit's symbolic loops and calls, `dr.freeze`, CUDA) needs to
//! evaluate a material with array operations, so that the physics stays
//! here. Prototype scope: Gaussian surfaces (isotropic or anisotropic), the
//! diffuse part f (without the coherent lobe and the cosine), Stam's formula
//! (not "energy": "conserving"). The export is one f32 array: a header of
//! `HEADER_LEN` values, then the tables it points to. The rule that combines
//! them ("gaussian-v1") is written out in docs/jit.md; the test
//! `rust-core/tests/jit_export.rs` runs it on the CPU from the array alone
//! against `Brdf::eval_spectral`, and scripts/jit_prototype.py with Dr.Jit.

use super::Brdf;
use crate::models::gaussian::series_table_export;
use crate::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Version of the layout and of the rule.
pub const FORMAT: u32 = 1;
/// Model code of the Gaussian rule "gaussian-v1".
pub const MODEL_GAUSSIAN: u32 = 1;
/// Values before the first table.
pub const HEADER_LEN: usize = 32;
/// Terms of the small-g sum the rule uses below the table (g < g_min).
pub const SMALL_G_TERMS: usize = 4;

/// Header slots (indices into the export).
pub mod slot {
    pub const FORMAT: usize = 0;
    pub const MODEL: usize = 1;
    pub const HEADER_LEN: usize = 2;
    pub const TOTAL_LEN: usize = 3;
    pub const SIGMA_UM: usize = 4;
    pub const CORR_X_UM: usize = 5;
    pub const CORR_Y_UM: usize = 6;
    pub const LAMBDA_MIN_NM: usize = 7;
    pub const LAMBDA_MAX_NM: usize = 8;
    pub const SERIES_OFFSET: usize = 9;
    pub const SERIES_N_G: usize = 10;
    pub const SERIES_N_RHO: usize = 11;
    pub const SERIES_LN_G_MIN: usize = 12;
    pub const SERIES_D_LN_G: usize = 13;
    pub const SERIES_D_RHO: usize = 14;
    pub const SERIES_G_MIN: usize = 15;
    pub const SERIES_G_MAX: usize = 16;
    pub const SERIES_RHO_MAX: usize = 17;
    pub const FRESNEL_OFFSET: usize = 18;
    pub const FRESNEL_ROWS: usize = 19;
    pub const FRESNEL_COS_STEPS: usize = 20;
    pub const FRESNEL_LAMBDA_OFFSET: usize = 21;
    pub const FRESNEL_ROW_OF_NM_OFFSET: usize = 22;
    pub const FRESNEL_ROW_OF_NM_LEN: usize = 23;
    pub const FRESNEL_MAX_ROW_STEPS: usize = 24;
    pub const RGB_OFFSET: usize = 25;
    pub const RGB_NODES: usize = 26;
    pub const RGB_COS_BINS: usize = 27;
    pub const RGB_LAMBDA_OFFSET: usize = 28;
    pub const SMALL_G_TERMS: usize = 29;
}

impl Brdf {
    /// The material's JIT export (layout and rule in docs/jit.md); None for
    /// what the prototype does not cover (models other than Gaussian,
    /// "energy": "conserving").
    pub fn jit_export(&self) -> Option<Vec<f32>> {
        if self.energy.is_some() {
            return None;
        }
        let surface = self.surface.gaussian()?.surface();
        let series = series_table_export();
        let fresnel = self.fresnel.export_grid((LAMBDA_MIN_NM, LAMBDA_MAX_NM));
        let (bins, weights) = self.rgb_rule.export_weights(&self.fresnel);

        let mut h = vec![0.0f64; HEADER_LEN];
        let mut body: Vec<f32> = Vec::new();
        let mut place = |h: &mut Vec<f64>, at: usize, values: &mut dyn Iterator<Item = f32>| {
            h[at] = (HEADER_LEN + body.len()) as f64;
            body.extend(values);
        };
        h[slot::FORMAT] = FORMAT as f64;
        h[slot::MODEL] = MODEL_GAUSSIAN as f64;
        h[slot::HEADER_LEN] = HEADER_LEN as f64;
        h[slot::SIGMA_UM] = surface.sigma_um;
        h[slot::CORR_X_UM] = surface.corr_x_um;
        h[slot::CORR_Y_UM] = surface.corr_y_um;
        h[slot::LAMBDA_MIN_NM] = LAMBDA_MIN_NM;
        h[slot::LAMBDA_MAX_NM] = LAMBDA_MAX_NM;

        h[slot::SERIES_N_G] = series.n_g as f64;
        h[slot::SERIES_N_RHO] = series.n_rho as f64;
        h[slot::SERIES_LN_G_MIN] = series.ln_g_min;
        h[slot::SERIES_D_LN_G] = series.d_ln_g;
        h[slot::SERIES_D_RHO] = series.d_rho;
        h[slot::SERIES_G_MIN] = series.g_min;
        h[slot::SERIES_G_MAX] = series.g_max;
        h[slot::SERIES_RHO_MAX] = series.rho_max;
        place(
            &mut h,
            slot::SERIES_OFFSET,
            &mut series.coefficients.iter().copied(),
        );

        h[slot::FRESNEL_ROWS] = fresnel.rows.len() as f64;
        h[slot::FRESNEL_COS_STEPS] = (fresnel.rows[0].len() - 1) as f64;
        h[slot::FRESNEL_ROW_OF_NM_LEN] = fresnel.row_of_nm.len() as f64;
        h[slot::FRESNEL_MAX_ROW_STEPS] = fresnel.max_row_steps() as f64;
        place(
            &mut h,
            slot::FRESNEL_OFFSET,
            &mut fresnel.rows.iter().flatten().map(|&v| v as f32),
        );
        place(
            &mut h,
            slot::FRESNEL_LAMBDA_OFFSET,
            &mut fresnel.lambda_nm.iter().map(|&v| v as f32),
        );
        place(
            &mut h,
            slot::FRESNEL_ROW_OF_NM_OFFSET,
            &mut fresnel.row_of_nm.iter().map(|&v| v as f32),
        );

        h[slot::RGB_NODES] = self.rgb_rule.len() as f64;
        h[slot::RGB_COS_BINS] = bins as f64;
        place(
            &mut h,
            slot::RGB_OFFSET,
            &mut weights.iter().flatten().map(|&v| v as f32),
        );
        place(
            &mut h,
            slot::RGB_LAMBDA_OFFSET,
            &mut self.rgb_rule.lambda_nm().iter().map(|&v| v as f32),
        );
        h[slot::SMALL_G_TERMS] = SMALL_G_TERMS as f64;
        h[slot::TOTAL_LEN] = (HEADER_LEN + body.len()) as f64;

        let mut out: Vec<f32> = h.iter().map(|&v| v as f32).collect();
        out.extend(body);
        Some(out)
    }
}
