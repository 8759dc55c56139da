//! The tables' two caches: in the process, and on disk between processes
//! (keyed by `table_key`: the grating, the grid and `SOLVER_VERSION`).

use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use super::{build, table_key, EfficiencyTable, Row, TableSpec};
use crate::rigorous::layers::Grating;
use crate::StamError;

/// Where tables are kept between processes: $STAM_CACHE_DIR, else
/// $XDG_CACHE_HOME/stam-diffraction, else ~/.cache/stam-diffraction. None
/// when none can be found (the table is then built in every process).
pub fn cache_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("STAM_CACHE_DIR") {
        return Some(PathBuf::from(dir));
    }
    if let Some(dir) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(dir).join("stam-diffraction"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("stam-diffraction"))
}

/// FNV-1a, for file names (the key itself is checked on reading).
fn hash(text: &str) -> u64 {
    text.bytes().fold(0xcbf29ce484222325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100000001b3)
    })
}

fn cache_path(key: &str) -> Option<PathBuf> {
    cache_dir().map(|d| d.join(format!("rigorous-{:016x}.bin", hash(key))))
}

fn write_cache(key: &str, table: &EfficiencyTable) -> std::io::Result<()> {
    let Some(path) = cache_path(key) else {
        return Ok(());
    };
    std::fs::create_dir_all(path.parent().expect("a file in the cache directory"))?;
    let mut bytes = Vec::new();
    bytes.extend_from_slice(&(key.len() as u64).to_le_bytes());
    bytes.extend_from_slice(key.as_bytes());
    bytes.extend_from_slice(&table.m_min.to_le_bytes());
    bytes.extend_from_slice(&table.m_max.to_le_bytes());
    bytes.extend_from_slice(&table.period_um.to_le_bytes());
    bytes.push(table.symmetric as u8);
    bytes.extend_from_slice(&(table.rows.len() as u64).to_le_bytes());
    for row in &table.rows {
        bytes.extend_from_slice(&(row.ky.len() as u64).to_le_bytes());
        for y in &row.ky {
            bytes.extend_from_slice(&y.to_le_bytes());
        }
        for v in row.values.iter().chain(&row.mueller) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    // Write then rename: a reader never sees half a file.
    let partial = path.with_extension(format!("{}.partial", std::process::id()));
    std::fs::File::create(&partial)?.write_all(&bytes)?;
    std::fs::rename(&partial, &path)
}

/// The table stored on disk under `key`, if any (and if it is whole).
pub fn table_from_disk(key: &str, spec: &TableSpec) -> Option<EfficiencyTable> {
    let mut bytes = Vec::new();
    std::fs::File::open(cache_path(key)?)
        .ok()?
        .read_to_end(&mut bytes)
        .ok()?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = bytes.get(at..at + n)?;
        at += n;
        Some(s)
    };
    let key_len = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    if take(key_len)? != key.as_bytes() {
        return None;
    }
    let m_min = i64::from_le_bytes(take(8)?.try_into().ok()?);
    let m_max = i64::from_le_bytes(take(8)?.try_into().ok()?);
    let period_um = f64::from_le_bytes(take(8)?.try_into().ok()?);
    let symmetric = take(1)?[0] != 0;
    let n_rows = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let orders = usize::try_from(m_max - m_min + 1).ok()?;
    let mut table = EfficiencyTable {
        spec: spec.clone(),
        m_min,
        m_max,
        period_um,
        symmetric,
        rows: Vec::new(),
        build_seconds: 0.0,
    };
    if n_rows != spec.n_lambda * table.n_kx_rows() {
        return None;
    }
    let mut rows = Vec::with_capacity(n_rows);
    for r in 0..n_rows {
        let n = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
        let (il, ix) = (r / table.n_kx_rows(), r % table.n_kx_rows());
        let mut row = Row::layout(
            table.step(table.lambda_nm(il)),
            table.row_kx(ix),
            spec.cover_eta,
            spec.nodes_per_gap,
        );
        let ky: Vec<f64> = take(8 * n)?
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        if ky != row.ky {
            return None;
        }
        let mut floats = |count: usize| -> Option<Vec<f32>> {
            Some(
                take(4 * count)?
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                    .collect(),
            )
        };
        row.values = floats(n * orders)?;
        if spec.polarised {
            row.mueller = floats(16 * n * orders)?;
        }
        rows.push(row);
    }
    table.rows = rows;
    Some(table)
}

type Cache = Mutex<HashMap<String, Arc<EfficiencyTable>>>;

fn memory_cache() -> &'static Cache {
    static CACHE: OnceLock<Cache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The table of `grating` on `spec`: from this process's cache, else the
/// disk cache, else built (and then stored in both).
pub fn table(grating: &Grating, spec: &TableSpec) -> Result<Arc<EfficiencyTable>, StamError> {
    let key = table_key(grating, spec);
    if let Some(t) = memory_cache().lock().unwrap().get(&key) {
        return Ok(t.clone());
    }
    let table = match table_from_disk(&key, spec) {
        Some(t) => t,
        None => {
            let t = build(grating, spec)?;
            if let Err(e) = write_cache(&key, &t) {
                eprintln!("stam: could not keep the rigorous table on disk ({e}); it will be built again next time");
            }
            t
        }
    };
    let table = Arc::new(table);
    memory_cache().lock().unwrap().insert(key, table.clone());
    Ok(table)
}
