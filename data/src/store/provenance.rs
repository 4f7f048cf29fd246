//! Where an import source comes from: the [`PROVENANCE_FILE`] sidecar that names its registry package, its
//! licence and a readable asset name, found in the source's folder or above.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};

/// Where a source comes from: the package and licence recorded per clip in `index.parquet`, and an optional
/// readable asset name for captions. Read from the nearest [`PROVENANCE_FILE`] in the source's folder or above.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
pub struct Provenance {
    #[serde(default)]
    pub source_package: String,
    #[serde(default)]
    pub licence: String,
    /// Readable asset name ("female soldier") for the captions of files in this folder.
    #[serde(default)]
    pub asset: Option<String>,
}

/// File name of a provenance sidecar: JSON `{"source_package": …, "licence": …, "asset": …}`.
pub const PROVENANCE_FILE: &str = "any4d-source.json";

/// The provenance of `path`: the nearest [`PROVENANCE_FILE`] in its folder or above (cached per folder).
pub(super) fn provenance_of(path: &Path, cache: &mut HashMap<PathBuf, Result<Provenance>>) -> Result<Provenance> {
    let mut dir = path.parent();
    let mut seen = Vec::new();
    let found = loop {
        let Some(d) = dir else { break Ok(Provenance::default()) };
        if let Some(p) = cache.get(d) {
            break p.clone();
        }
        seen.push(d.to_path_buf());
        let file = d.join(PROVENANCE_FILE);
        if file.is_file() {
            break std::fs::read(&file)
                .map_err(|e| DataError::io(&file, e))
                .and_then(|b| serde_json::from_slice(&b).map_err(|e| DataError::new(&file, "json", e.to_string())));
        }
        dir = d.parent();
    };
    for d in seen {
        cache.insert(d, found.clone());
    }
    found
}
