//! Sampling a height map: the diffuse kernel is the map's spectrum T over
//! the frequency nu = k (u, v) / (2 pi); the lobe draws a cell of T at the
//! mirror's kappa = 2 k cos_i (the two nodes around it, by their linear
//! weights) from the node's alias table, a point uniformly inside the
//! cell, and maps nu to wo. Its density is the drawn law's: piecewise
//! constant over the cells, exact. The coherent lobe takes |chi|^2 of the
//! probability (the share of |P|^2 in the delta by Parseval), at most
//! 1 - 2^-20 so that the diffuse part keeps a density wherever f > 0.

use super::{HeightMap, SpectrumTable};
use crate::program::Real;
use crate::sampling::warps::uv_to_direction;
use crate::sampling::{draw_alias, Component};
use crate::spectrum::{in_band, wavenumber_per_um};
use glam::DVec3;
use std::f64::consts::PI;

/// The largest coherent probability.
pub(super) const MAX_COHERENT_PROBABILITY: f64 = 1.0 - 1.0 / (1u64 << 20) as f64;

/// The cells of node `node`, or of `node + 1` with probability `upper`.
#[derive(Clone)]
pub struct Lobe {
    k_per_um: f64,
    node: usize,
    upper: f64,
}

/// Where the mirror's kappa falls among the nodes: the lower node and the
/// upper one's weight.
pub(super) fn mirror_nodes<R: Real>(table: &SpectrumTable, k_per_um: R, cos_i: R) -> (R, R) {
    let (_, i, t) = table.place_in_s(k_per_um * cos_i * 2.0, table.nodes);
    (i, t)
}

impl SpectrumTable {
    /// The frequency nu of position (fx, fy) on the grid (cell centres at
    /// integers), any `Real`.
    pub(super) fn grid_to_nu<R: Real>(&self, f: R) -> R {
        (f - (self.tile / 2) as f64) * (1.0 / self.tile_um)
    }

    /// The grid position of frequency nu.
    pub(super) fn nu_to_grid<R: Real>(&self, nu: R) -> R {
        nu * self.tile_um + (self.tile / 2) as f64
    }

    /// The cell (an index into a node's tile^2) holding the grid position
    /// (fx, fy), and whether there is one.
    pub(super) fn cell_at<R: Real>(&self, fx: R, fy: R) -> (R, R::Mask) {
        let n = self.tile as f64;
        let (cx, cy) = ((fx + 0.5).floor(), (fy + 0.5).floor());
        let inside = cx.ge(0.0) & cx.lt(n) & cy.ge(0.0) & cy.lt(n);
        (cy.clamp(0.0, n - 1.0) * n + cx.clamp(0.0, n - 1.0), inside)
    }

    /// The density per unit nu^2 of the cells of `node` at `cell`: the
    /// cell's share of the node's total over its area 1 / tile_um^2.
    fn cell_density(&self, node: usize, cell: usize) -> f64 {
        let cells = self.tile * self.tile;
        let [scale, flat] = self.node_density(node);
        self.values[node * cells + cell] as f64 * scale + flat
    }

    /// Node `node`'s cell density per unit nu^2 as value * scale + flat:
    /// the cell's share of the node's total over the cell's area 1 /
    /// tile_um^2, or, for an empty node (whose alias table is the uniform
    /// law), the same for every cell. The programs read these pairs.
    pub(super) fn node_density(&self, node: usize) -> [f64; 2] {
        let area = self.tile_um * self.tile_um;
        let total = self.totals[node];
        if total > 0.0 {
            [area / total, 0.0]
        } else {
            [0.0, area / (self.tile * self.tile) as f64]
        }
    }
}

impl crate::sampling::Lobe for Lobe {
    type Model = HeightMap;

    fn sample(&self, model: &HeightMap, wi: DVec3, t: f64, r1: f64, r2: f64) -> Option<DVec3> {
        let table = model.table();
        let lower = 1.0 - self.upper;
        let (node, t) = if t < lower {
            (self.node, t / lower)
        } else {
            (self.node + 1, (t - lower) / self.upper)
        };
        let cells = table.tile * table.tile;
        let base = 2 * node * cells;
        let cell = draw_alias(r1, cells, |at: f64| table.alias[base + at as usize] as f64) as usize;
        let (cx, cy) = ((cell % table.tile) as f64, (cell / table.tile) as f64);
        let nu_x = table.grid_to_nu(cx + t.clamp(0.0, 1.0) - 0.5);
        let nu_y = table.grid_to_nu(cy + r2 - 0.5);
        let scale = 2.0 * PI / self.k_per_um;
        uv_to_direction(wi, nu_x * scale, nu_y * scale)
    }

    fn pdf(&self, model: &HeightMap, wi: DVec3, wo: DVec3, _negligible: f64) -> f64 {
        let table = model.table();
        let to_nu = self.k_per_um / (2.0 * PI);
        let (u, v) = (-(wi.x + wo.x), -(wi.y + wo.y));
        let fx = table.nu_to_grid(u * to_nu);
        let fy = table.nu_to_grid(v * to_nu);
        let (cell, inside) = table.cell_at(fx, fy);
        if !inside {
            return 0.0;
        }
        let cell = cell as usize;
        let mut p_nu = (1.0 - self.upper) * table.cell_density(self.node, cell);
        if self.upper > 0.0 {
            p_nu += self.upper * table.cell_density(self.node + 1, cell);
        }
        // nu = k (u, v) / 2 pi, and d(u, v) = cos_o d(omega).
        p_nu * to_nu * to_nu * wo.z
    }
}

impl HeightMap {
    /// The one-wavelength strategy at unit wi above the horizon.
    pub(super) fn component(&self, wi: DVec3, lambda_nm: f64) -> Component<Lobe> {
        if !(lambda_nm.is_finite() && in_band(lambda_nm)) {
            return Component::cosine_only();
        }
        let table = self.table();
        let k = wavenumber_per_um(lambda_nm);
        let p_coh = self
            .coherent_with(k, wi.z, self.fetch_chi2())
            .clamp(0.0, MAX_COHERENT_PROBABILITY);
        let (node, upper) = mirror_nodes(table, k, wi.z);
        // An empty node's alias table is the uniform law over the cells: a
        // lobe stands for every node, as in the programs.
        let lobe = Lobe {
            k_per_um: k,
            node: node as usize,
            upper,
        };
        Component::new(p_coh, 1.0 - p_coh, Some(lobe))
    }
}
