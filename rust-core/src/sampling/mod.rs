//! Sampling machinery that knows no surface model: the defensive mixture
//! of a coherent lobe, a cosine/uniform part and a model's lobe
//! (`mixture`), the strategy table over incidence and wavelength
//! (`table`), hemisphere warps and inverse CDFs (`warps`), the band density
//! of the RGB strategies (`band`) and the deterministic RNG of the tables
//! (`rng`). The models' lobes live with their models (`models::*::sampling`).
//! See docs/sampling.md.

mod alias;
mod band;
mod mixture;
pub mod program;
mod rng;
mod table;
pub mod warps;

pub use alias::{draw_alias, AliasTable};
pub use band::{band_density, rgb_sampling_nodes, RGB_BAND_NM, RGB_SAMPLING_NODES};
pub use mixture::{Component, Components, Lobe, Mixture, SampleResult, DEFENSIVE_FRACTION};
pub use rng::SplitMix64;
pub use table::StrategyTable;
pub use warps::inverse_normal;
