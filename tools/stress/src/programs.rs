//! The material's programs (`stam_brdf_export_program`, stam.h) under
//! hostile inputs: an exported array decoded with `stam::program::decode`
//! and run lane by lane with the core's CPU executor in f32, as a
//! renderer's kernel runs it. This is how the stress runner and the fuzzers
//! reach the programs. The contract checked (stam.h's list of kinds):
//! - the array: format 4, its own length, decodable, with the kind's
//!   numbers of inputs and outputs;
//! - eval, pdf and coherent kinds: every output finite and >= 0 at any
//!   input; a coherent probability <= 1; 0 where a direction the kind
//!   reads is certainly not above the horizon (a non-finite component, zero
//!   length, z <= 0), and for a spectral f or coherent reflectance at a
//!   wavelength outside the band;
//! - sample kinds: the coherent flag 0 or 1; with uniforms in [0, 1] a
//!   finite direction, a unit vector where it is above the horizon, above
//!   it where coherent, and a failed sample (below the horizon, not
//!   coherent) for an incidence certainly below it;
//! - between kinds (same lane, same wavelength or RGB): the pdf is > 0 at
//!   a glossy sample's direction (its density there) and wherever f > 0
//!   (an unbiased estimator needs both).

use stam::program::{decode, Program, FORMAT};
use stam::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Number of program kinds (STAM_PROGRAM_KINDS).
pub const KINDS: u32 = 8;

/// (inputs, outputs) of program kind `kind` (n_wavelengths 0) or of a
/// mixture kind over n_wavelengths, as stam.h gives them
/// (stam_program_io); None for neither.
pub fn io(kind: u32, n_wavelengths: u32) -> Option<(u32, usize)> {
    let (mut n_in, mut n_out) = (0u32, 0u32);
    let known = unsafe { stam::ffi::stam_program_io(kind, n_wavelengths, &mut n_in, &mut n_out) };
    (known == 1).then_some((n_in, n_out as usize))
}

/// Names of the kinds, for messages.
pub const NAMES: [&str; KINDS as usize] = [
    "EVAL_RGB",
    "EVAL_SPECTRAL",
    "PDF_RGB",
    "PDF_SPECTRAL",
    "SAMPLE_RGB",
    "SAMPLE_SPECTRAL",
    "COHERENT_RGB",
    "COHERENT_SPECTRAL",
];

const EVAL_RGB: usize = 0;
const PDF_RGB: usize = 2;
const SAMPLE_RGB: usize = 4;
const COHERENT_RGB: usize = 6;

/// Whether the kind takes a wavelength (its last input).
pub fn spectral(kind: u32) -> bool {
    kind % 2 == 1
}

/// One lane's values; each kind reads the ones it takes (stam.h): wi;
/// then wo (eval, pdf) or u (sample); then lambda (spectral kinds).
#[derive(Clone, Copy, Debug)]
pub struct Lane {
    pub wi: [f32; 3],
    pub wo: [f32; 3],
    pub u: [f32; 3],
    pub lambda: f32,
}

impl Lane {
    /// The lane's inputs to a program of `kind`.
    pub fn inputs(&self, kind: u32) -> Vec<f32> {
        let mut v = self.wi.to_vec();
        match kind / 2 {
            0 | 1 => v.extend(self.wo),
            2 => v.extend(self.u),
            _ => {}
        }
        if spectral(kind) {
            v.push(self.lambda);
        }
        v
    }

    /// The same lane with each uniform folded into [0, 1) (a renderer's
    /// sampler never gives others): |u| mod 1, 0.5 for NaN and infinities.
    pub fn with_valid_uniforms(&self) -> Lane {
        let fold = |x: f32| {
            if x.is_finite() {
                x.abs().fract()
            } else {
                0.5
            }
        };
        Lane {
            u: self.u.map(fold),
            ..*self
        }
    }
}

/// A direction that no executor can take for one above the horizon: a
/// non-finite component, zero length, or z <= 0.
fn certainly_not_upper(d: [f32; 3]) -> bool {
    !d.iter().all(|c| c.is_finite()) || d == [0.0; 3] || !(d[2] > 0.0)
}

fn certainly_out_of_band(lambda: f32) -> bool {
    !(lambda as f64 >= LAMBDA_MIN_NM && lambda as f64 <= LAMBDA_MAX_NM)
}

fn in_unit_interval(u: [f32; 3]) -> bool {
    u.iter().all(|x| (0.0..=1.0).contains(x))
}

/// The program of an exported array of `kind`, checked: the header's
/// format and length, `decode`, and the kind's inputs and outputs.
pub fn decode_checked(kind: u32, array: &[f32]) -> Result<Program, String> {
    let name = NAMES[kind as usize];
    if array.len() < 8 || array[0] != FORMAT as f32 || array[5] != array.len() as f32 {
        return Err(format!(
            "{name}: header {:?} (format {FORMAT}, the array's length {})",
            &array[..array.len().min(8)],
            array.len()
        ));
    }
    let p = decode(array).ok_or_else(|| format!("{name}: the exported array does not decode"))?;
    let (n_in, n_out) = io(kind, 0).ok_or_else(|| format!("{name}: not a kind"))?;
    if p.n_inputs != n_in || p.outputs.len() != n_out {
        return Err(format!(
            "{name}: {} inputs and {} outputs, not {n_in} and {n_out}",
            p.n_inputs,
            p.outputs.len()
        ));
    }
    Ok(p)
}

/// What [`check`] did.
#[derive(Clone, Debug, Default)]
pub struct Checked {
    /// Lanes run (one program on one lane).
    pub runs: u64,
    /// Contract violations, one line each.
    pub violations: Vec<String>,
}

/// Runs each program (`programs[kind]`, None where the material has none)
/// on every lane in f32 and checks the outputs and the kinds against each
/// other (the module's list).
pub fn check(programs: &[Option<Program>], lanes: &[Lane]) -> Checked {
    let mut c = Checked::default();
    let mut regs = Vec::new();
    // outputs[kind][lane]
    let mut outputs: Vec<Vec<Vec<f32>>> = vec![Vec::new(); KINDS as usize];
    for (kind, p) in programs.iter().enumerate() {
        let Some(p) = p else { continue };
        let k = kind as u32;
        let name = NAMES[kind];
        for lane in lanes {
            let mut out = vec![0f32; p.outputs.len()];
            p.run_into(&lane.inputs(k), &mut regs, &mut out);
            c.runs += 1;
            let mut fail = |what: &str| {
                c.violations
                    .push(format!("{name} {what}: outputs {out:?} at {lane:?}"))
            };
            if kind / 2 == SAMPLE_RGB / 2 {
                let (wo, coherent) = ([out[0], out[1], out[2]], out[3]);
                if coherent != 0.0 && coherent != 1.0 {
                    fail("coherent flag neither 0 nor 1");
                } else if in_unit_interval(lane.u) && !wo.iter().all(|x| x.is_finite()) {
                    fail("a direction not finite");
                } else if wo[2] > 0.0 && wo.iter().all(|x| x.is_finite()) {
                    let len = wo.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
                    if !((len - 1.0).abs() <= 1e-4) {
                        fail("a direction above the horizon that is not unit");
                    }
                }
                if coherent == 1.0 && !(wo[2] > 0.0) {
                    fail("a coherent sample not above the horizon");
                }
                if certainly_not_upper(lane.wi) && (wo[2] > 0.0 || coherent != 0.0) {
                    fail("a sample for an incidence below the horizon");
                }
            } else {
                if !out.iter().all(|x| x.is_finite() && *x >= 0.0) {
                    fail("not finite and >= 0");
                }
                let reads_wo = kind < SAMPLE_RGB;
                let undefined =
                    certainly_not_upper(lane.wi) || (reads_wo && certainly_not_upper(lane.wo));
                if undefined && out.iter().any(|&x| x != 0.0) {
                    fail("not 0 for a direction below the horizon");
                }
                if kind >= COHERENT_RGB && !(out[out.len() - 1] <= 1.0) {
                    fail("a coherent probability > 1");
                }
                let zero_out_of_band = k == 1 || k == 7;
                if zero_out_of_band && certainly_out_of_band(lane.lambda) && !(out[0] == 0.0) {
                    fail("not 0 for a wavelength outside the band");
                }
            }
            outputs[kind].push(out);
        }
    }
    // Between kinds: the pdf at a glossy sample's direction and where f > 0.
    for mode in 0..2 {
        let Some(pdf) = &programs[PDF_RGB + mode] else {
            continue;
        };
        for (i, lane) in lanes.iter().enumerate() {
            if let Some(f) = outputs[EVAL_RGB + mode].get(i) {
                if f.iter().any(|&x| x > 0.0) && !(outputs[PDF_RGB + mode][i][0] > 0.0) {
                    c.violations.push(format!(
                        "{}: f {f:?} > 0 where {} is {} at {lane:?}",
                        NAMES[EVAL_RGB + mode],
                        NAMES[PDF_RGB + mode],
                        outputs[PDF_RGB + mode][i][0]
                    ));
                }
            }
            let Some(s) = outputs[SAMPLE_RGB + mode].get(i) else {
                continue;
            };
            // A glossy sample clearly above the horizon (MIN_COS is 1e-12).
            if s[3] == 0.0 && s[2] > 1e-6 && s.iter().all(|x| x.is_finite()) {
                let at = Lane {
                    wo: [s[0], s[1], s[2]],
                    ..*lane
                };
                let mut p = [0f32];
                pdf.run_into(&at.inputs((PDF_RGB + mode) as u32), &mut regs, &mut p);
                c.runs += 1;
                if !(p[0] > 0.0) {
                    c.violations.push(format!(
                        "{}: density {} at the glossy sample {s:?} of {} at {lane:?}",
                        NAMES[PDF_RGB + mode],
                        p[0],
                        NAMES[SAMPLE_RGB + mode]
                    ));
                }
            }
        }
    }
    c
}

/// Wavelengths a mixture lane carries besides its own: the lane's
/// wavelength first (hostile or not), then these.
pub const MIXTURE_OTHERS: [f32; 3] = [450.0, 551.5, 680.0];

/// Checks the mixture programs over 4 wavelengths (`stam_brdf_export_
/// mixture_program`: pdf, sample, coherent, in the order of
/// STAM_MIXTURE_*) against the spectral kinds' programs (`singles`, by
/// STAM_PROGRAM_* code) on every lane in f32: the pdf the mean of
/// PDF_SPECTRAL's, the sample SAMPLE_SPECTRAL's at the wavelength u0 picks
/// (u0 remapped), the coherent outputs COHERENT_SPECTRAL's and their
/// probabilities' mean; within 1e-6 of each other's magnitude.
pub fn check_mixtures(
    mixtures: &[Program],
    singles: &[Option<Program>],
    lanes: &[Lane],
) -> Checked {
    let mut c = Checked::default();
    let (Some(pdf1), Some(sample1), Some(coherent1)) = (&singles[3], &singles[5], &singles[7])
    else {
        c.violations.push("no spectral programs to mix".into());
        return c;
    };
    let names = ["MIXTURE_PDF", "MIXTURE_SAMPLE", "MIXTURE_COHERENT"];
    for (k, p) in mixtures.iter().enumerate() {
        if Some((p.n_inputs, p.outputs.len())) != io(k as u32, 4) {
            c.violations.push(format!(
                "{}: inputs / outputs {:?}",
                names[k],
                (p.n_inputs, p.outputs.len())
            ));
            return c;
        }
    }
    let close = |a: &[f32], b: &[f32]| {
        a.len() == b.len()
            && a.iter().zip(b).all(|(x, y)| {
                x.to_bits() == y.to_bits()
                    || (x - y).abs() <= 1e-6 * x.abs().max(y.abs()).max(1e-30)
            })
    };
    for lane in lanes.iter().map(Lane::with_valid_uniforms) {
        let lambdas = [
            lane.lambda,
            MIXTURE_OTHERS[0],
            MIXTURE_OTHERS[1],
            MIXTURE_OTHERS[2],
        ];
        let single = |p: &Program, mut inputs: Vec<f32>, lambda: f32| {
            inputs.push(lambda);
            p.run(&inputs)
        };
        let with = |mut inputs: Vec<f32>| {
            inputs.extend(lambdas);
            inputs
        };
        let (wi, wiwo, wiu) = (
            lane.wi.to_vec(),
            [lane.wi, lane.wo].concat(),
            [lane.wi, lane.u].concat(),
        );
        // pdf
        let got = mixtures[0].run(&with(wiwo.clone()));
        let mut sum = 0f32;
        for &l in &lambdas {
            sum += single(pdf1, wiwo.clone(), l)[0];
        }
        let want = [sum * 0.25];
        // sample
        let x = lane.u[0] * 4.0;
        let j = x.floor().clamp(0.0, 3.0);
        let u0 = (x - j).clamp(0.0, 1.0 - 1.0 / 16_777_216.0);
        let got_s = mixtures[1].run(&with(wiu.clone()));
        let want_s = single(
            sample1,
            [&lane.wi[..], &[u0, lane.u[1], lane.u[2]]].concat(),
            lambdas[j as usize],
        );
        // coherent
        let got_c = mixtures[2].run(&with(wi.clone()));
        let each: Vec<Vec<f32>> = lambdas
            .iter()
            .map(|&l| single(coherent1, wi.clone(), l))
            .collect();
        let mut want_c: Vec<f32> = each.iter().map(|o| o[0]).collect();
        want_c.push(each.iter().map(|o| o[1]).sum::<f32>() * 0.25);
        c.runs += 3 + 9;
        for (name, got, want) in [
            (names[0], &got[..], &want[..]),
            (names[1], &got_s[..], &want_s[..]),
            (names[2], &got_c[..], &want_c[..]),
        ] {
            if !close(got, want) {
                c.violations.push(format!(
                    "{name} {got:?}, the spectral programs mixed {want:?}, at {lane:?}"
                ));
            }
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use stam::program::Builder;

    fn lane(wi: [f32; 3], wo: [f32; 3], u: [f32; 3], lambda: f32) -> Lane {
        Lane { wi, wo, u, lambda }
    }

    /// The checks are not vacuous: programs that break each rule are
    /// reported, and the material's own programs pass.
    #[test]
    fn checks_catch_broken_programs() {
        let up = lane([0.0, 0.6, 0.8], [0.0, -0.6, 0.8], [0.2, 0.3, 0.4], 550.0);
        let below = lane([0.0, 0.6, -0.8], [0.0, -0.6, 0.8], [0.2, 0.3, 0.4], 550.0);
        // An eval of (wi.y - 0.7, wi.y, wi.y): negative, not 0 below the
        // horizon, > 0 where the pdf (0 everywhere) is not.
        let b = Builder::new();
        let ins: Vec<_> = (0..6).map(|_| b.input()).collect();
        let eval = b.finish(&[ins[1] - 0.7, ins[1], ins[1]]);
        let b = Builder::new();
        let _: Vec<_> = (0..6).map(|_| b.input()).collect();
        let pdf = b.finish(&[b.c(0.0)]);
        let mut programs: Vec<Option<Program>> = vec![None; 8];
        programs[EVAL_RGB] = Some(eval);
        programs[PDF_RGB] = Some(pdf);
        let c = check(&programs, &[up, below]);
        let has = |s: &str| c.violations.iter().any(|v| v.contains(s));
        assert!(has("not finite and >= 0"), "{:?}", c.violations);
        assert!(has("not 0 for a direction below the horizon"));
        assert!(has("> 0 where PDF_RGB is 0"));
        assert_eq!(c.runs, 4);
        // A sampler that returns wo = u unnormalised, flag 0.5.
        let b = Builder::new();
        let ins: Vec<_> = (0..6).map(|_| b.input()).collect();
        let sample = b.finish(&[ins[3], ins[4], ins[5], b.c(0.5)]);
        let mut programs: Vec<Option<Program>> = vec![None; 8];
        programs[SAMPLE_RGB] = Some(sample);
        let c = check(&programs, &[up]);
        assert!(
            c.violations[0].contains("coherent flag"),
            "{:?}",
            c.violations
        );
        // The header and the kind's shape.
        let array = programs[SAMPLE_RGB].as_ref().unwrap().encode();
        assert!(decode_checked(4, &array).is_ok());
        assert!(decode_checked(6, &array).unwrap_err().contains("inputs"));
        let mut bad = array.clone();
        bad[0] = 1.0;
        assert!(decode_checked(4, &bad).unwrap_err().contains("header"));
        assert!(decode_checked(4, &array[..array.len() - 1]).is_err());
    }

    #[test]
    fn a_material_passes() {
        let brdf =
            stam::Brdf::from_json(r#"{"surface": "gaussian", "sigma_um": 0.1, "corr_um": 2}"#)
                .unwrap();
        let programs: Vec<Option<Program>> = stam::material::program::ProgramKind::ALL
            .iter()
            .map(|&k| {
                brdf.program(k)
                    .map(|p| decode_checked(k as u32, &p.encode()).unwrap())
            })
            .collect();
        assert!(programs[2..].iter().all(Option::is_some));
        let lanes = [
            lane([0.0, 0.6, 0.8], [0.1, -0.6, 0.8], [0.2, 0.3, 0.4], 550.0),
            lane([f32::NAN, 0.0, 1.0], [0.0, 0.0, -1.0], [0.9, 0.0, 1.0], 0.0),
            lane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.5, 0.5], f32::NAN),
        ];
        let c = check(&programs, &lanes);
        assert!(c.violations.is_empty(), "{:?}", c.violations);
        assert!(c.runs >= 6 * 3);
    }
}
