//! `index.parquet` of a dataset store: one row per accepted clip and per rejected file (docs/method.md §2.2 manifest).

use std::fs::File;
use std::path::Path;

use polars::prelude::*;

use crate::error::{DataError, Result};

use super::{INDEX_FILE, Split};

/// Whether a row is a stored clip or a rejected source file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Ok,
    Rejected,
}

impl Status {
    /// "ok" or "rejected".
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Rejected => "rejected",
        }
    }
}

/// One row of `index.parquet`.
#[derive(Debug, Clone, PartialEq)]
pub struct IndexRow {
    /// Clip id (for a rejected file: its file name).
    pub id: String,
    /// Canonical source path (or `synth:<seed>:<index>`); with the id it keys re-imports.
    pub source: String,
    /// "bin", "obj-seq", "gltf", "glb", "synth" (or "" if the format was not recognised).
    pub format: String,
    /// T, N_v and M of a stored clip; `None` for a rejected file.
    pub frames: Option<u32>,
    pub vertices: Option<u32>,
    pub faces: Option<u32>,
    /// Caption ("" for a rejected file).
    pub caption: String,
    /// Split of a stored clip; `None` for a rejected file.
    pub split: Option<Split>,
    /// Ok or rejected.
    pub status: Status,
    /// Why a file was rejected ("" when ok).
    pub reason: String,
    /// Object uid used by the split.
    pub object: String,
    /// xxh3-64 of the clip's record in `clips.bin` ([`super::checksum`]); `None` for a rejected file and for every
    /// row of a store written before checksums existed (re-import to add them).
    pub checksum: Option<u64>,
    /// Licence of the source ("" when unknown), from the source's provenance sidecar.
    pub licence: String,
    /// Registry package the source came from ("" when unknown).
    pub source_package: String,
}

/// Name of the checksum column (absent in stores made before it existed).
pub const CHECKSUM_COLUMN: &str = "checksum";

fn polars_err(path: &Path, field: &str, e: PolarsError) -> DataError {
    DataError::new(path, field, e.to_string())
}

/// Write `rows` to `dir/index.parquet` through a temporary file and a rename.
pub fn write_index(dir: &Path, rows: &[IndexRow]) -> Result<()> {
    let path = dir.join(INDEX_FILE);
    let tmp = dir.join(format!("{INDEX_FILE}.tmp"));
    let strings = |f: fn(&IndexRow) -> &str| rows.iter().map(f).collect::<Vec<&str>>();
    let columns = vec![
        Column::new("id".into(), strings(|r| &r.id)),
        Column::new("source".into(), strings(|r| &r.source)),
        Column::new("format".into(), strings(|r| &r.format)),
        Column::new("frames".into(), rows.iter().map(|r| r.frames).collect::<Vec<_>>()),
        Column::new("vertices".into(), rows.iter().map(|r| r.vertices).collect::<Vec<_>>()),
        Column::new("faces".into(), rows.iter().map(|r| r.faces).collect::<Vec<_>>()),
        Column::new("caption".into(), strings(|r| &r.caption)),
        Column::new(
            "split".into(),
            rows.iter().map(|r| r.split.map(Split::as_str)).collect::<Vec<_>>(),
        ),
        Column::new("status".into(), strings(|r| r.status.as_str())),
        Column::new("reason".into(), strings(|r| &r.reason)),
        Column::new("object".into(), strings(|r| &r.object)),
        Column::new(
            CHECKSUM_COLUMN.into(),
            rows.iter().map(|r| r.checksum).collect::<Vec<_>>(),
        ),
        Column::new("licence".into(), strings(|r| &r.licence)),
        Column::new("source_package".into(), strings(|r| &r.source_package)),
    ];
    let mut df = DataFrame::new(rows.len(), columns).map_err(|e| polars_err(&path, "columns", e))?;
    let written = (|| {
        let file = File::create(&tmp).map_err(|e| DataError::io(&tmp, e))?;
        ParquetWriter::new(&file)
            .with_compression(ParquetCompression::Uncompressed)
            .finish(&mut df)
            .map_err(|e| polars_err(&tmp, "parquet", e))?;
        file.sync_all().map_err(|e| DataError::io(&tmp, e))?;
        std::fs::rename(&tmp, &path).map_err(|e| DataError::io(&path, e))
    })();
    if written.is_err() {
        // Best effort: the error that matters is the one above.
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Read `dir/index.parquet` of a one-file store (a shard); a missing column, a wrong type or an unknown
/// status/split names the column and row. [`super::read_index`] reads either kind of store.
pub fn read_index_file(dir: &Path) -> Result<Vec<IndexRow>> {
    let path = dir.join(INDEX_FILE);
    let file = File::open(&path).map_err(|e| DataError::io(&path, e))?;
    let df = ParquetReader::new(file)
        .finish()
        .map_err(|e| polars_err(&path, "parquet", e))?;
    let col = |name: &str| df.column(name).map_err(|e| polars_err(&path, name, e));
    let strs = |name: &str| -> Result<Vec<Option<String>>> {
        let c = col(name)?;
        let ca = c.str().map_err(|e| polars_err(&path, name, e))?;
        Ok(ca.iter().map(|s| s.map(str::to_owned)).collect())
    };
    let ints = |name: &str| -> Result<Vec<Option<u32>>> {
        let c = col(name)?;
        let ca = c.u32().map_err(|e| polars_err(&path, name, e))?;
        Ok(ca.iter().collect())
    };
    let required = |name: &str| -> Result<Vec<String>> {
        strs(name)?
            .into_iter()
            .enumerate()
            .map(|(i, s)| {
                s.ok_or_else(|| DataError::new(&path, format!("{name} row {i}"), "null in a required column"))
            })
            .collect()
    };
    let (id, source, format, caption, status, reason, object) = (
        required("id")?,
        required("source")?,
        required("format")?,
        required("caption")?,
        required("status")?,
        required("reason")?,
        required("object")?,
    );
    let (frames, vertices, faces, split) = (ints("frames")?, ints("vertices")?, ints("faces")?, strs("split")?);
    // Stores written before checksums have no such column: every row reads as "no checksum".
    let checksums: Vec<Option<u64>> = match df.column(CHECKSUM_COLUMN) {
        Err(_) => vec![None; df.height()],
        Ok(c) => c
            .u64()
            .map_err(|e| polars_err(&path, CHECKSUM_COLUMN, e))?
            .iter()
            .collect(),
    };
    // Columns added later: a store written before them reads as "".
    let optional = |name: &str| -> Result<Vec<String>> {
        if df.column(name).is_err() {
            return Ok(vec![String::new(); df.height()]);
        }
        Ok(strs(name)?.into_iter().map(Option::unwrap_or_default).collect())
    };
    let (licence, source_package) = (optional("licence")?, optional("source_package")?);
    let mut rows = Vec::with_capacity(df.height());
    for i in 0..df.height() {
        let status = match status[i].as_str() {
            "ok" => Status::Ok,
            "rejected" => Status::Rejected,
            other => {
                return Err(DataError::new(
                    &path,
                    format!("status row {i}"),
                    format!("unknown status {other:?}"),
                ));
            }
        };
        let split = match &split[i] {
            None => None,
            Some(s) => Some(
                Split::parse(s)
                    .ok_or_else(|| DataError::new(&path, format!("split row {i}"), format!("unknown split {s:?}")))?,
            ),
        };
        rows.push(IndexRow {
            id: id[i].clone(),
            source: source[i].clone(),
            format: format[i].clone(),
            frames: frames[i],
            vertices: vertices[i],
            faces: faces[i],
            caption: caption[i].clone(),
            split,
            status,
            reason: reason[i].clone(),
            object: object[i].clone(),
            checksum: checksums[i],
            licence: licence[i].clone(),
            source_package: source_package[i].clone(),
        });
    }
    Ok(rows)
}
