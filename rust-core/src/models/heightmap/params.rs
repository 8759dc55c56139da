//! Parameters of a measured or synthetic height map (docs/parameters.md,
//! docs/heightmap.md).

use crate::error::StamError;
use crate::json::{KeyDoc, Reader};
use crate::program::ParamId;
use serde_json::{json, Map, Value};

/// Accepted ranges, shared by the validator, the docs and the stress tests.
pub mod range {
    /// Sample spacing: from atomic-force-microscope pixels to a coarse
    /// profilometer's.
    pub const PIXEL_UM: (f64, f64) = (1e-4, 100.0);
    /// Micrometres per unit of the file's values.
    pub const HEIGHT_SCALE_UM: (f64, f64) = (1e-9, 1e6);
    /// Welch tile edge (a power of two): a program indexes nodes x tile^2
    /// values in f32, exact to 2^24.
    pub const TILE_PX: (usize, usize) = (16, 512);
    pub const RGB_NODES: (usize, usize) = (4, crate::models::MAX_RGB_NODES);
}

/// Default node count of the RGB rule: a map's spectrum is as smooth in
/// the wavelength as a Gaussian's at this resolution (docs/heightmap.md).
pub const DEFAULT_RGB_NODES: usize = 24;
pub const DEFAULT_HEIGHT_SCALE_UM: f64 = 1.0;

#[derive(Clone, Debug, PartialEq)]
pub struct HeightMapParams {
    /// The map's file (.npy, .exr, .tif, .png or .csv), as the host resolved it.
    pub file: String,
    pub pixel_um: f64,
    pub height_scale_um: f64,
    /// Welch tile edge in pixels; None: chosen from the map's correlation
    /// length (`welch::default_tile`).
    pub tile_px: Option<usize>,
    pub rgb_nodes: usize,
}

impl crate::models::ModelParams for HeightMapParams {
    const SURFACE_NAMES: &'static [&'static str] = &["heightmap"];

    fn rgb_nodes(&self) -> usize {
        self.rgb_nodes
    }

    /// None: the map is data, and its tables are built constants.
    fn table_params(&self) -> Vec<(ParamId, f64)> {
        Vec::new()
    }

    fn with_param(&self, _id: ParamId, _value: f64) -> HeightMapParams {
        self.clone()
    }

    fn reference(_surface: &str) -> Vec<KeyDoc> {
        vec![
            KeyDoc::text(
                "file",
                "the height map: a .npy array (float or integer, rows along y), an OpenEXR \
                 image (its one channel, or Y, or R), a gray TIFF (floats or integers) or \
                 PNG (8 or 16 bits) image, or a .csv table of numbers, one row of the map \
                 per line",
                "a path".into(),
            )
            .required(),
            KeyDoc::number(
                "pixel_um",
                "spacing of the map's samples",
                "um",
                range::PIXEL_UM,
                false,
            )
            .required(),
            KeyDoc::number(
                "height_scale_um",
                "micrometres per unit of the map's values",
                "um",
                range::HEIGHT_SCALE_UM,
                false,
            )
            .default(json!(DEFAULT_HEIGHT_SCALE_UM)),
            KeyDoc::integer(
                "tile_px",
                "edge of the Welch tiles (a power of two, at most the map's smaller edge); \
                 default: 20 correlation lengths of the map, 32-256",
                range::TILE_PX,
            ),
            KeyDoc::integer(
                "rgb_nodes",
                "wavelength nodes of the RGB rule",
                range::RGB_NODES,
            )
            .default(json!(DEFAULT_RGB_NODES)),
        ]
    }

    fn resolved(&self, _given: &Map<String, Value>, out: &mut Map<String, Value>) {
        out.insert("file".into(), json!(self.file));
        out.insert("pixel_um".into(), json!(self.pixel_um));
        out.insert("height_scale_um".into(), json!(self.height_scale_um));
        if let Some(tile) = self.tile_px {
            out.insert("tile_px".into(), json!(tile));
        }
        out.insert("rgb_nodes".into(), json!(self.rgb_nodes));
    }

    fn parse(_surface: &str, r: &Reader) -> Result<HeightMapParams, StamError> {
        r.check_keys(&[
            "file",
            "pixel_um",
            "height_scale_um",
            "tile_px",
            "rgb_nodes",
        ])?;
        let file = r.string("file")?.ok_or_else(|| {
            StamError::new(
                "missing parameter 'file' for surface 'heightmap' (a .npy, .exr, .tif, .png or .csv height map)",
            )
        })?;
        let tile_px = r.integer("tile_px", range::TILE_PX)?;
        if let Some(tile) = tile_px {
            if !tile.is_power_of_two() {
                return Err(StamError::new(format!(
                    "parameter 'tile_px' = {tile} must be a power of two (16, 32, ..., 512)"
                )));
            }
        }
        Ok(HeightMapParams {
            file,
            pixel_um: r.required("pixel_um", range::PIXEL_UM, false, " um")?,
            height_scale_um: r
                .ranged("height_scale_um", range::HEIGHT_SCALE_UM, false, " um")?
                .unwrap_or(DEFAULT_HEIGHT_SCALE_UM),
            tile_px,
            rgb_nodes: r
                .integer("rgb_nodes", range::RGB_NODES)?
                .unwrap_or(DEFAULT_RGB_NODES),
        })
    }
}
