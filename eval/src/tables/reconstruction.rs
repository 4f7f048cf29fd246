//! P-Table 5 (docs/method.md §6.2 (E4)): VAE reconstruction of validation clips, every frame encoded and decoded
//! (posterior mean), RMSE and Chamfer unscaled, one row per VAE; and the decoded sequences' (E5) jerk against the
//! input's, pooled over the clips: the frame-to-frame noise the VAE alone adds. With [`Reconstruction::per_vertex`]
//! it also writes where on each mesh the error lies ([`super::vertex_errors`]).

use std::path::PathBuf;

use any4d_data::Clip;

use super::PAPER_CLIPS;
use super::summary::{ClipRecord, Layout, MetricColumn, col, csv, markdown, pooled, summarize, write_clip_parquet};
use super::vertex_errors::{VertexRecord, vertex_errors, write_vertex_parquet};
use super::{TableOptions, TableReport, header_for, progress_bar, write_text};
use crate::metrics::{Motion, vae_reconstruction};
use crate::protocol::{Manifest, ManifestOptions, StoreSource};

use crate::error::{EvalError, Result};

/// Title and columns of P-Table 5.
pub const LAYOUT: Layout = Layout {
    title: "Table 5: VAE reconstruction on validation clips",
    columns: COLUMNS,
    k_column: true,
};

const COLUMNS: &[MetricColumn] = &[
    col("rmse", "RMSE", 1.0),
    col("chamfer", "Chamfer", 1.0),
    pooled("jerk_pooled", "jerk", "jerk_gt", "jerk Σ/ΣGT"),
];

/// A VAE (or any encode → decode pair) for P-Table 5.
pub trait Reconstructor {
    /// Row label, e.g. `framewise` or `sequencewise`.
    fn label(&self) -> String;
    /// Encode and decode every frame of a normalised clip.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N]` rows; returns `[T, N]` rows.
    fn reconstruct(&self, clip: &Clip) -> Result<Vec<[f32; 3]>>;

    /// The vertices of `clip`'s frame 0 whose features become the latent tokens, when the VAE has such anchors.
    fn anchors(&self, _clip: &Clip) -> Option<Vec<u32>> {
        None
    }
}

/// The options of P-Table 5.
#[derive(Debug, Clone, PartialEq)]
pub struct Reconstruction {
    /// Items in the manifest (100).
    pub clips: usize,
    /// Reuse this manifest instead of drawing one.
    pub manifest: Option<PathBuf>,
    /// Also write `vertices.parquet`: every vertex's error and features ([`super::vertex_errors`]).
    pub per_vertex: bool,
}

impl Default for Reconstruction {
    fn default() -> Self {
        Self {
            clips: PAPER_CLIPS,
            manifest: None,
            per_vertex: false,
        }
    }
}

impl Reconstruction {
    /// Runs the table: every VAE of `opts.vaes` reconstructs every manifest item.
    pub fn run(&self, opts: &TableOptions) -> Result<TableReport> {
        if opts.vaes.is_empty() {
            return Err(EvalError::invalid("eval run", "vaes", "table5 needs at least one VAE"));
        }
        let source = StoreSource::open(&opts.data, opts.split)?;
        let manifest_path = opts.out.join("manifest.json");
        let manifest = match &self.manifest {
            Some(p) => Manifest::load(p)?,
            None => {
                let mo = ManifestOptions {
                    n_clips: self.clips,
                    seeds: vec![0],
                    split: opts.split.name().into(),
                    ..ManifestOptions::table1(opts.data.display().to_string())
                };
                Manifest::build(&source.candidates(mo.frames), &mo, &opts.data.display().to_string())?
            }
        };
        manifest.save(&manifest_path)?;
        let bar = progress_bar(opts.progress, manifest.clips.len(), "reconstructing")?;
        let mut records = Vec::new();
        let mut vertex_records = Vec::new();
        for (i, item) in manifest.clips.iter().enumerate() {
            let (gt, _) = source.item(item, manifest.frames)?;
            for vae in &opts.vaes {
                let rec = vae.reconstruct(&gt)?;
                let err = |e: crate::metrics::EvalError| EvalError::invalid(&gt.id, vae.label(), e.to_string());
                let decoded = Motion::new(&rec, gt.frames, gt.n_vertices).map_err(err)?;
                let r = vae_reconstruction(decoded, Motion::from_clip(&gt).map_err(err)?).map_err(err)?; // (E4)
                if self.per_vertex {
                    vertex_records.push(VertexRecord {
                        method: vae.label(),
                        item: i,
                        clip_id: item.clip.id.clone(),
                        errors: vertex_errors(&gt, &rec, vae.anchors(&gt).as_deref())?,
                    });
                }
                let metrics = [
                    ("rmse".to_string(), r.rmse),
                    ("chamfer".to_string(), r.chamfer),
                    ("jerk".to_string(), r.jerk),
                    ("jerk_gt".to_string(), r.jerk_gt),
                ]
                .into_iter()
                .collect();
                records.push(ClipRecord {
                    method: vae.label(),
                    placement: "all_frames".into(),
                    k_extra: 0,
                    seed: 0,
                    item: i,
                    clip_id: item.clip.id.clone(),
                    metrics,
                });
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
        let mut files = vec![manifest_path.clone()];
        let parquet = opts.out.join("clips.parquet");
        write_clip_parquet(&records, &parquet)?;
        files.push(parquet);
        if self.per_vertex {
            let path = opts.out.join("vertices.parquet");
            write_vertex_parquet(&vertex_records, &path)?;
            files.push(path);
        }
        let rows = summarize(&records, &LAYOUT)?;
        let header = header_for(opts, &manifest_path);
        let md = markdown(&LAYOUT, &rows, &header);
        write_text(&opts.out.join("summary.md"), &md, &mut files)?;
        write_text(&opts.out.join("summary.csv"), &csv(&LAYOUT, &rows, &header), &mut files)?;
        Ok(TableReport {
            title: LAYOUT.title,
            rows,
            markdown: md,
            files,
        })
    }
}
