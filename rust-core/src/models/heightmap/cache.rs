//! One table per map while a material holds it: the energy table's white
//! twin, a plugin's rebuilt material and a scene's second object of the
//! same map read the file and run its FFTs once. Keyed by the file's path,
//! length and modification time (a rewritten map is a new map) and the
//! parameters the table depends on.

use super::map::{read_map, HeightField};
use super::params::HeightMapParams;
use super::welch::SpectrumTable;
use crate::error::StamError;
use std::sync::{Arc, Mutex, Weak};
use std::time::SystemTime;

#[derive(Clone, PartialEq)]
struct Key {
    path: String,
    len: u64,
    modified: Option<SystemTime>,
    pixel_um: u64,
    height_scale_um: u64,
    tile_px: Option<usize>,
}

static TABLES: Mutex<Vec<(Key, Weak<SpectrumTable>)>> = Mutex::new(Vec::new());

/// The table of `p`'s map, shared while any material holds it.
pub(super) fn table(p: &HeightMapParams) -> Result<Arc<SpectrumTable>, StamError> {
    let meta = std::fs::metadata(&p.file).map_err(|e| {
        StamError::new(format!(
            "parameter 'file': cannot read height map '{}': {e}",
            p.file
        ))
    })?;
    let key = Key {
        path: p.file.clone(),
        len: meta.len(),
        modified: meta.modified().ok(),
        pixel_um: p.pixel_um.to_bits(),
        height_scale_um: p.height_scale_um.to_bits(),
        tile_px: p.tile_px,
    };
    // A poisoned lock only means another build panicked: the list of weak
    // references is still valid.
    let mut tables = TABLES.lock().unwrap_or_else(|e| e.into_inner());
    tables.retain(|(_, t)| t.strong_count() > 0);
    if let Some(table) = tables
        .iter()
        .find(|(k, _)| *k == key)
        .and_then(|(_, t)| t.upgrade())
    {
        return Ok(table);
    }
    let (nx, ny, values) = read_map(&p.file)?;
    let what = format!("'{}'", p.file);
    let field = HeightField::new(nx, ny, values, p.pixel_um, p.height_scale_um, &what)?;
    if let Some(tile) = p.tile_px {
        if tile > nx.min(ny) {
            return Err(StamError::new(format!(
                "parameter 'tile_px' = {tile} is larger than the map {what} ({nx} x {ny})"
            )));
        }
    }
    let table = Arc::new(SpectrumTable::build(&field, p.tile_px));
    tables.push((key, Arc::downgrade(&table)));
    Ok(table)
}
