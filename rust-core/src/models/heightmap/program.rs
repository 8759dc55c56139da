//! The height-map model's programs for tracing renderers (crate::program,
//! docs/jit.md): the native path's reads (`SpectrumTable::read`,
//! `chi2_read`, `mirror_nodes`, the grid's cells, `draw_alias`), written
//! once over `program::Real`, with a gather as their fetch.
//!
//! - K: 8 gathers (two nodes' bilinear cells) and one log; RGB: the RGB
//!   table's trilinear read (24 gathers, one log: `rgb.rs`), or for a map
//!   too sharp for it the same K at each node of the RGB rule, then the
//!   rule with the Fresnel term folded in (`RgbRule::integrate_program`).
//! - The coherent lobe: |chi|^2 by two gathers per wavelength.
//! - Sampling: the native strategy (`sampling.rs`) exactly: the component
//!   (RGB: one of the four sampling wavelengths), then the coherent lobe,
//!   the defensive part (half cosine, half uniform) or a cell of the
//!   mirror's node drawn from its alias table; the pdf is the cells'
//!   piecewise-constant density.
//! - No parameter: the map is data, its tables built constants.

use super::sampling::{mirror_nodes, MAX_COHERENT_PROBABILITY};
use super::{HeightMap, SpectrumTable};
use crate::models::{FactorMaker, FactorProgram, SampleProgram, Shading, SurfacePrograms};
use crate::optics::geometry::MIN_COS;
use crate::optics::program::{PairProgram, Vec3};
use crate::program::{Builder, Table, Value};
use crate::sampling::program::{
    component_choice, defensive_density_program, defensive_direction_program, pick,
    unit_interval_program, U_MAX,
};
use crate::sampling::{draw_alias, rgb_sampling_nodes, DEFENSIVE_FRACTION};
use crate::spectrum::wavenumber_per_um;
use std::f64::consts::PI;

/// Per node: the cell density's scale and flat part
/// (`SpectrumTable::node_density`).
fn node_density_table(table: &SpectrumTable) -> Vec<f32> {
    (0..table.nodes)
        .flat_map(|node| table.node_density(node).map(|x| x as f32))
        .collect()
}

/// One component of the strategy at wi: its wavenumber, coherent
/// probability and mirror nodes.
struct ComponentProgram<'a> {
    k: Value<'a>,
    p_coh: Value<'a>,
    node: Value<'a>,
    upper: Value<'a>,
}

impl HeightMap {
    fn components<'a>(
        &self,
        b: &'a Builder,
        chi2: Table,
        cos_i: Value<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Vec<ComponentProgram<'a>> {
        let ks: Vec<Value<'a>> = match lambda_nm {
            Some(lambda) => vec![wavenumber_per_um(lambda)],
            None => rgb_sampling_nodes()
                .iter()
                .map(|&l| b.c(wavenumber_per_um(l)))
                .collect(),
        };
        ks.into_iter()
            .map(|k| {
                let p_coh = self
                    .coherent_with(k, cos_i, |at| b.gather(chi2, at))
                    .clamp(0.0, MAX_COHERENT_PROBABILITY);
                let (node, upper) = mirror_nodes(self.table(), k, cos_i);
                ComponentProgram {
                    k,
                    p_coh,
                    node,
                    upper,
                }
            })
            .collect()
    }

    fn chi2_table(&self, b: &Builder) -> Table {
        b.table(self.table().chi2.clone())
    }
}

impl SurfacePrograms for HeightMap {
    fn kernel_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
    ) -> Option<Value<'a>> {
        let values = b.table(self.table().values.clone());
        Some(
            self.table()
                .kernel(k_per_um, pair.w.abs(), pair.u, pair.v, |at| {
                    b.gather(values, at)
                }),
        )
    }

    /// The RGB table's read (`rgb.rs`: 8 points of 3 channels, one log).
    /// Height-map tables are colour-neutral (the material scales outside):
    /// no per-wavelength factor.
    fn reflectance_rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        pair: &PairProgram<'a>,
        factor: Option<FactorMaker<'_, 'a>>,
    ) -> Option<[Value<'a>; 3]> {
        if factor.is_some() {
            return None;
        }
        let w_abs = pair.w.abs();
        if let Some(rgb_table) = self.rgb_table(shading) {
            let values = b.table(rgb_table.values.clone());
            return Some(rgb_table.read(w_abs, pair.u, pair.v, |at| b.gather(values, at)));
        }
        // A map too sharp for the table: the rule's nodes.
        let rule = shading.rgb_rule;
        let table = b.table(self.table().values.clone());
        let values: Vec<Value> = rule
            .k_per_um
            .iter()
            .map(|&k| {
                self.table()
                    .kernel(b.c(k), w_abs, pair.u, pair.v, |at| b.gather(table, at))
            })
            .collect();
        Some(rule.integrate_program(b, shading.fresnel, pair.cos_half, &values))
    }

    fn coherent_spectral_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        cos_i: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        let chi2 = self.chi2_table(b);
        let k = wavenumber_per_um(lambda_nm);
        let r = shading.fresnel.program(b, cos_i, lambda_nm);
        Some(r * self.coherent_with(k, cos_i, |at| b.gather(chi2, at)))
    }

    fn coherent_rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        cos_i: Value<'a>,
        factor: Option<&dyn FactorProgram<'a>>,
    ) -> Option<[Value<'a>; 3]> {
        if factor.is_some() {
            return None;
        }
        let rule = shading.rgb_rule;
        let chi2 = self.chi2_table(b);
        let values: Vec<Value> = rule
            .k_per_um
            .iter()
            .map(|&k| {
                self.table()
                    .chi2_read(cos_i * (2.0 * k), |at| b.gather(chi2, at))
            })
            .collect();
        Some(rule.integrate_program(b, shading.fresnel, cos_i, &values))
    }

    fn coherent_probability_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let chi2 = self.chi2_table(b);
        let comps = self.components(b, chi2, wi[2], lambda_nm);
        let count = comps.len() as f64;
        let sum = comps
            .iter()
            .map(|c| c.p_coh)
            .reduce(|a, x| a + x)
            .expect("a component");
        Some(sum * (1.0 / count))
    }

    fn sample_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        let table = self.table();
        let chi2 = self.chi2_table(b);
        let alias = b.table(table.alias.clone());
        let [r0, r1, r2] = u.map(unit_interval_program);
        // The component (RGB: one of four wavelengths), then its part, as
        // `Mixture::sample_direction`.
        let comps = self.components(b, chi2, wi[2], lambda_nm);
        let (j, r) = component_choice(r0, comps.len());
        let field = |f: fn(&ComponentProgram<'a>) -> Value<'a>| {
            pick(j, &comps.iter().map(f).collect::<Vec<_>>())
        };
        let (k, p_coh) = (field(|c| c.k), field(|c| c.p_coh));
        let (node, upper) = (field(|c| c.node), field(|c| c.upper));
        let coherent = r.lt(p_coh);
        let rest = r - p_coh;
        let p_rest = 1.0 - p_coh;
        let p_def = p_rest * DEFENSIVE_FRACTION;
        let p_lobe = p_rest * (1.0 - DEFENSIVE_FRACTION);
        // Defensive: half cosine-weighted, half uniform.
        let phi = r2 * (2.0 * PI);
        let defensive = defensive_direction_program(rest.lt(p_def * 0.5), r1, phi.cos(), phi.sin());
        // The lobe: the node (by the upper one's weight), a cell of it from
        // r1, the point inside the cell from the rest of r0 and r2.
        let t = ((rest - p_def) / p_lobe).clamp(0.0, U_MAX);
        let lower = 1.0 - upper;
        let use_upper = t.ge(lower);
        let t = use_upper
            .select((t - lower) / upper, t / lower)
            .clamp(0.0, 1.0);
        let node = use_upper.select(node + 1.0, node);
        let cells = (table.tile * table.tile) as f64;
        let base = node * (2.0 * cells);
        let cell = draw_alias(r1, table.tile * table.tile, |at| b.gather(alias, base + at));
        let n = table.tile as f64;
        let cy = ((cell + 0.5) * (1.0 / n)).floor();
        let cx = cell - cy * n;
        let scale = (k * (1.0 / (2.0 * PI))).max(1e-30);
        let lu = table.grid_to_nu(cx + t - 0.5) / scale;
        let lv = table.grid_to_nu(cy + r2 - 0.5) / scale;
        let lx = -wi[0] - lu;
        let ly = -wi[1] - lv;
        let rr = lx * lx + ly * ly;
        let lz = (1.0 - rr).max(0.0).sqrt();
        let lobe_ok = rr.lt(1.0) & lz.gt(MIN_COS);
        let lobe = [
            lobe_ok.select(lx, 0.0),
            lobe_ok.select(ly, 0.0),
            lobe_ok.select(lz, -1.0),
        ];
        let is_def = rest.lt(p_def);
        let mirror = [-wi[0], -wi[1], wi[2]];
        Some(SampleProgram {
            wo: std::array::from_fn(|c| {
                coherent.select(mirror[c], is_def.select(defensive[c], lobe[c]))
            }),
            coherent,
        })
    }

    fn pdf_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let table = self.table();
        let chi2 = self.chi2_table(b);
        let values = b.table(table.values.clone());
        let density = b.table(node_density_table(table));
        let cells = (table.tile * table.tile) as f64;
        let (u, v) = (-(wi[0] + wo[0]), -(wi[1] + wo[1]));
        let defensive = defensive_density_program(wo[2]);
        let comps = self.components(b, chi2, wi[2], lambda_nm);
        let count = comps.len() as f64;
        let sum = comps
            .iter()
            .map(|c| {
                let to_nu = c.k * (1.0 / (2.0 * PI));
                let fx = table.nu_to_grid(u * to_nu);
                let fy = table.nu_to_grid(v * to_nu);
                let (cell, inside) = table.cell_at(fx, fy);
                let at_node = |node: Value<'a>| {
                    let value = b.gather(values, node * cells + cell);
                    let scale = b.gather(density, node * 2.0);
                    let flat = b.gather(density, node * 2.0 + 1.0);
                    value * scale + flat
                };
                let p_nu = at_node(c.node) * (1.0 - c.upper) + at_node(c.node + 1.0) * c.upper;
                let lobe = inside.select(p_nu * to_nu * to_nu * wo[2], 0.0);
                (1.0 - c.p_coh)
                    * (defensive * DEFENSIVE_FRACTION + lobe * (1.0 - DEFENSIVE_FRACTION))
            })
            .reduce(|a, x| a + x)
            .expect("a component");
        Some(sum * (1.0 / count))
    }
}
