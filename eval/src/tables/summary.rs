//! Paper-shaped result tables (docs/method.md §6.1, §6.4: P-Tables 1, 2, 4, 5): per-clip records to parquet, summaries
//! to Markdown and CSV. Each metric is averaged over clips per seed, then reported as mean ± 95 % confidence
//! half-width over seeds, t_{0.975, n−1} · sd / √n (Student t with n − 1 degrees of freedom, sample sd).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use any4d_data::io::write_atomic;
use polars::prelude::{Column, DataFrame, ParquetReader, ParquetWriter, SerReader};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};

/// How a table is laid out: its title, its metric columns and whether rows carry their own K_x.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layout {
    /// Title line of the Markdown summary.
    pub title: &'static str,
    /// The metric columns: (record key, header, scale).
    pub columns: &'static [MetricColumn],
    /// Whether the K_x column shows each row's extra keyframes (`false`: fixed keyframes, printed as `–`).
    pub k_column: bool,
}

/// One metric column of a summary table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MetricColumn {
    /// Key in [`ClipRecord::metrics`] (or, pooled, the column's own name in the CSV).
    pub key: &'static str,
    /// Column header.
    pub header: &'static str,
    /// Multiplier applied when printing (100 where the paper scales).
    pub scale: f64,
    /// How the clips of one seed combine.
    pub aggregate: Aggregate,
}

/// How a column combines the clips of one seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Aggregate {
    /// The mean over clips of the record's value under the column's key.
    Mean,
    /// Σ `num` / Σ `den` over the clips: a ratio of means, which clips with a near-zero `den` (a ground truth that
    /// barely moves, for a jerk ratio) cannot dominate as they dominate the mean of per-clip ratios. NaN when Σ `den`
    /// is 0.
    Pooled { num: &'static str, den: &'static str },
}

/// A metric column: record key, header, scale (100 where the paper prints × 100).
pub const fn col(key: &'static str, header: &'static str, scale: f64) -> MetricColumn {
    MetricColumn {
        key,
        header,
        scale,
        aggregate: Aggregate::Mean,
    }
}

/// A pooled ratio column named `key`: Σ `num` / Σ `den` over the clips of a seed ([`Aggregate::Pooled`]) on which
/// both are defined (a NaN in either leaves the clip out of both sums).
pub const fn pooled(key: &'static str, num: &'static str, den: &'static str, header: &'static str) -> MetricColumn {
    pooled_scaled(key, num, den, header, 1.0)
}

/// [`pooled`] printed × `scale`.
pub const fn pooled_scaled(
    key: &'static str,
    num: &'static str,
    den: &'static str,
    header: &'static str,
    scale: f64,
) -> MetricColumn {
    MetricColumn {
        key,
        header,
        scale,
        aggregate: Aggregate::Pooled { num, den },
    }
}

/// The metrics of one (method, keyframe set, seed, clip) generation.
#[derive(Debug, Clone, PartialEq)]
pub struct ClipRecord {
    /// Method label (e.g. `keyframe_rf`).
    pub method: String,
    /// Placement label (`random`, `every_4`, …).
    pub placement: String,
    /// Extra keyframes K_x (number of keyframes − 2).
    pub k_extra: usize,
    /// Base noise seed.
    pub seed: u64,
    /// Position of the item in the manifest.
    pub item: usize,
    /// Clip id.
    pub clip_id: String,
    /// Metric name → value (raw, unscaled). Every record of one table has the same names.
    pub metrics: BTreeMap<String, f64>,
}

/// Names the method, checkpoint, text encoder and data behind a table (printed in its header).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TableHeader {
    /// Dataset directory or description, and split.
    pub data: String,
    /// Manifest file the clips and keyframes come from.
    pub manifest: String,
    /// Text encoder of the RF runs (`scratch`, `minilm`, `clip_l14`, or `none`).
    pub text_encoder: String,
    /// Method label → checkpoint (run folder / step) or `none` for training-free methods.
    pub checkpoints: BTreeMap<String, String>,
    /// Backend and device (P-Table 4).
    pub device: String,
    /// Protocol choices a reader must know to compare the table with the paper's (one line each).
    #[serde(default)]
    pub notes: Vec<String>,
}

/// Mean and 95 % confidence half-width over seeds (`None` with one seed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub mean: f64,
    pub ci95: Option<f64>,
    /// Number of seeds.
    pub n: usize,
}

/// One summary row: a method at one keyframe setting, with an estimate per table column.
#[derive(Debug, Clone, PartialEq)]
pub struct SummaryRow {
    pub method: String,
    pub placement: String,
    pub k_extra: usize,
    /// Number of clips averaged per seed.
    pub clips: usize,
    pub values: Vec<Estimate>,
}

/// Student-t 97.5 % quantiles for 1..=30 degrees of freedom; 1.96 (normal) beyond.
const T975: [f64; 30] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131, 2.120,
    2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
];

/// Mean ± t_{0.975, n−1} · sd / √n of `xs` (sample sd); no interval for fewer than two values.
pub fn mean_ci95(xs: &[f64]) -> Estimate {
    let n = xs.len();
    let mean = xs.iter().sum::<f64>() / n.max(1) as f64;
    if n < 2 {
        return Estimate { mean, ci95: None, n };
    }
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let t = T975.get(n - 2).copied().unwrap_or(1.96);
    Estimate {
        mean,
        ci95: Some(t * var.sqrt() / (n as f64).sqrt()),
        n,
    }
}

/// Group records by (method, placement, K_x), average each column over clips per seed, then over seeds.
/// Rows keep the order in which their methods first appear, then ascending K_x.
pub fn summarize(records: &[ClipRecord], layout: &Layout) -> Result<Vec<SummaryRow>> {
    let columns = layout.columns;
    let mut method_order: Vec<&str> = Vec::new();
    // (method, placement, k) → seed → (numerator and denominator sums per column, clip count)
    type PerSeed = BTreeMap<u64, (Vec<(f64, f64)>, usize)>;
    let mut groups: BTreeMap<(usize, &str, usize), PerSeed> = BTreeMap::new();
    for r in records {
        let m = match method_order.iter().position(|&m| m == r.method) {
            Some(i) => i,
            None => {
                method_order.push(&r.method);
                method_order.len() - 1
            }
        };
        let entry = groups
            .entry((m, r.placement.as_str(), r.k_extra))
            .or_default()
            .entry(r.seed)
            .or_insert_with(|| (vec![(0.0, 0.0); columns.len()], 0));
        let get = |key: &str| {
            r.metrics.get(key).copied().ok_or_else(|| {
                EvalError::invalid(
                    &r.clip_id,
                    key,
                    format!("missing from the record of method {}", r.method),
                )
            })
        };
        for (c, col) in columns.iter().enumerate() {
            let (num, den) = match col.aggregate {
                Aggregate::Mean => (get(col.key)?, 1.0),
                Aggregate::Pooled { num, den } => {
                    let (num, den) = (get(num)?, get(den)?);
                    // A clip on which the quantity is undefined (NaN: the jerk of a clip under 4 frames) adds
                    // nothing to either sum; the ratio is over the clips that have it.
                    if num.is_nan() || den.is_nan() {
                        continue;
                    }
                    (num, den)
                }
            };
            entry.0[c].0 += num;
            entry.0[c].1 += den;
        }
        entry.1 += 1;
    }
    let mut rows = Vec::new();
    for ((m, placement, k), seeds) in groups {
        let clips = seeds.values().map(|(_, n)| *n).max().unwrap_or(0);
        let values = (0..columns.len())
            .map(|c| {
                let per_seed: Vec<f64> = seeds
                    .values()
                    .map(|(sums, _)| {
                        let (num, den) = sums[c];
                        if den == 0.0 { f64::NAN } else { num / den }
                    })
                    .collect();
                mean_ci95(&per_seed)
            })
            .collect();
        rows.push(SummaryRow {
            method: method_order[m].to_string(),
            placement: placement.to_string(),
            k_extra: k,
            clips,
            values,
        });
    }
    Ok(rows)
}

/// Write the per-clip records as parquet: columns method, placement, k_extra, seed, item, clip_id, then one f64
/// column per metric name (all records must carry the same names).
pub fn write_clip_parquet(records: &[ClipRecord], path: &Path) -> Result<()> {
    let names: Vec<&String> = records.first().map_or_else(Vec::new, |r| r.metrics.keys().collect());
    for r in records {
        if r.metrics.len() != names.len() || !names.iter().all(|n| r.metrics.contains_key(*n)) {
            return Err(EvalError::invalid(
                path,
                "metrics",
                format!(
                    "record of {} / {} has metrics {:?}, expected {names:?}",
                    r.method,
                    r.clip_id,
                    r.metrics.keys()
                ),
            ));
        }
    }
    let mut cols = vec![
        Column::new(
            "method".into(),
            records.iter().map(|r| r.method.as_str()).collect::<Vec<_>>(),
        ),
        Column::new(
            "placement".into(),
            records.iter().map(|r| r.placement.as_str()).collect::<Vec<_>>(),
        ),
        Column::new(
            "k_extra".into(),
            records.iter().map(|r| r.k_extra as u32).collect::<Vec<_>>(),
        ),
        Column::new("seed".into(), records.iter().map(|r| r.seed).collect::<Vec<_>>()),
        Column::new("item".into(), records.iter().map(|r| r.item as u32).collect::<Vec<_>>()),
        Column::new(
            "clip_id".into(),
            records.iter().map(|r| r.clip_id.as_str()).collect::<Vec<_>>(),
        ),
    ];
    for name in &names {
        cols.push(Column::new(
            name.as_str().into(),
            records.iter().map(|r| r.metrics[*name]).collect::<Vec<_>>(),
        ));
    }
    let mut df =
        DataFrame::new(records.len(), cols).map_err(|e| EvalError::invalid(path, "dataframe", e.to_string()))?;
    let mut buf = Vec::new();
    ParquetWriter::new(&mut buf)
        .finish(&mut df)
        .map_err(|e| EvalError::invalid(path, "parquet", e.to_string()))?;
    Ok(write_atomic(path, &buf)?)
}

/// Read records written by [`write_clip_parquet`]; every column after `clip_id` is a metric.
pub fn read_clip_parquet(path: &Path) -> Result<Vec<ClipRecord>> {
    let file = std::fs::File::open(path).map_err(|e| EvalError::io(path, e))?;
    let df = ParquetReader::new(file)
        .finish()
        .map_err(|e| EvalError::invalid(path, "parquet", e.to_string()))?;
    let perr = |field: &str, e: polars::prelude::PolarsError| EvalError::invalid(path, field, e.to_string());
    let col = |name: &str| df.column(name).map_err(|e| perr(name, e));
    let strs = |name: &str| -> Result<Vec<String>> {
        let c = col(name)?;
        let ca = c.str().map_err(|e| perr(name, e))?;
        ca.iter()
            .enumerate()
            .map(|(i, v)| {
                v.map(str::to_owned)
                    .ok_or_else(|| EvalError::invalid(path, format!("{name} row {i}"), "null"))
            })
            .collect()
    };
    let (method, placement, clip_id) = (strs("method")?, strs("placement")?, strs("clip_id")?);
    let u32s = |name: &str| -> Result<Vec<u32>> {
        let c = col(name)?;
        let ca = c.u32().map_err(|e| perr(name, e))?;
        ca.iter()
            .enumerate()
            .map(|(i, v)| v.ok_or_else(|| EvalError::invalid(path, format!("{name} row {i}"), "null")))
            .collect()
    };
    let (k_extra, item) = (u32s("k_extra")?, u32s("item")?);
    let seed: Vec<u64> = {
        let c = col("seed")?;
        let ca = c.u64().map_err(|e| perr("seed", e))?;
        ca.iter()
            .enumerate()
            .map(|(i, v)| v.ok_or_else(|| EvalError::invalid(path, format!("seed row {i}"), "null")))
            .collect::<Result<_>>()?
    };
    let fixed = ["method", "placement", "k_extra", "seed", "item", "clip_id"];
    let mut metrics: Vec<(String, Vec<f64>)> = Vec::new();
    for c in df.columns() {
        let name = c.name().as_str();
        if fixed.contains(&name) {
            continue;
        }
        let ca = c.f64().map_err(|e| perr(name, e))?;
        let values = ca
            .iter()
            .enumerate()
            .map(|(i, v)| v.ok_or_else(|| EvalError::invalid(path, format!("{name} row {i}"), "null")))
            .collect::<Result<Vec<f64>>>()?;
        metrics.push((name.to_string(), values));
    }
    Ok((0..df.height())
        .map(|i| ClipRecord {
            method: method[i].clone(),
            placement: placement[i].clone(),
            k_extra: k_extra[i] as usize,
            seed: seed[i],
            item: item[i] as usize,
            clip_id: clip_id[i].clone(),
            metrics: metrics.iter().map(|(n, v)| (n.clone(), v[i])).collect(),
        })
        .collect())
}

fn fmt_estimate(e: &Estimate, scale: f64) -> String {
    match e.ci95 {
        Some(ci) => format!("{:.4} ± {:.4}", e.mean * scale, ci * scale),
        None => format!("{:.4}", e.mean * scale),
    }
}

pub(super) fn header_lines(title: &str, header: &TableHeader, seeds: usize) -> String {
    let mut s = format!("# {title}\n\n");
    let _ = writeln!(s, "- data: {}", header.data);
    let _ = writeln!(s, "- manifest: {}", header.manifest);
    let _ = writeln!(s, "- text encoder: {}", header.text_encoder);
    for (m, ckpt) in &header.checkpoints {
        let _ = writeln!(s, "- method `{m}`: checkpoint {ckpt}");
    }
    if !header.device.is_empty() {
        let _ = writeln!(s, "- backend / device: {}", header.device);
    }
    for note in &header.notes {
        let _ = writeln!(s, "- {note}");
    }
    let ci = if seeds > 1 {
        format!("mean over clips per seed, then mean ± 95 % CI over {seeds} seeds (Student t, n − 1 dof, sample sd)")
    } else {
        "mean over clips, one seed (no confidence interval)".to_string()
    };
    let _ = writeln!(s, "- values: {ci}; lower is better\n");
    s
}

/// The Markdown summary of a table: a header naming data, manifest, text encoder and checkpoints, then one row per
/// method and keyframe setting, values scaled as in the paper.
pub fn markdown(layout: &Layout, rows: &[SummaryRow], header: &TableHeader) -> String {
    let seeds = rows
        .iter()
        .flat_map(|r| r.values.iter().map(|v| v.n))
        .max()
        .unwrap_or(0);
    let mut s = header_lines(layout.title, header, seeds);
    let cols = layout.columns;
    s.push_str("| Method | Placement | K_x | Clips |");
    for c in cols {
        let _ = write!(s, " {} |", c.header);
    }
    s.push_str("\n|---|---|---|---|");
    s.push_str(&"---|".repeat(cols.len()));
    s.push('\n');
    for r in rows {
        // P-Table 2 has fixed keyframes every 15 frames, no K_x column of its own.
        let k = if layout.k_column {
            r.k_extra.to_string()
        } else {
            "–".to_string()
        };
        let _ = write!(s, "| {} | {} | {} | {} |", r.method, r.placement, k, r.clips);
        for (v, c) in r.values.iter().zip(cols) {
            let _ = write!(s, " {} |", fmt_estimate(v, c.scale));
        }
        s.push('\n');
    }
    s
}

/// The CSV summary: one row per method and setting, `<key>_mean` and `<key>_ci95` per column (scaled as in the
/// Markdown; empty CI with one seed), and the checkpoint, text encoder and data on every row.
pub fn csv(layout: &Layout, rows: &[SummaryRow], header: &TableHeader) -> String {
    let cols = layout.columns;
    let mut s = String::from("method,placement,k_extra,clips,seeds");
    for c in cols {
        let _ = write!(s, ",{0}_mean,{0}_ci95", c.key);
    }
    s.push_str(",scale,checkpoint,text_encoder,data\n");
    for r in rows {
        let seeds = r.values.first().map_or(0, |v| v.n);
        let _ = write!(
            s,
            "{},{},{},{},{}",
            csv_field(&r.method),
            csv_field(&r.placement),
            r.k_extra,
            r.clips,
            seeds
        );
        for (v, c) in r.values.iter().zip(cols) {
            let ci = v.ci95.map_or(String::new(), |x| format!("{}", x * c.scale));
            let _ = write!(s, ",{},{}", v.mean * c.scale, ci);
        }
        let scale = cols
            .iter()
            .map(|c| format!("{}", c.scale))
            .collect::<Vec<_>>()
            .join("/");
        let ckpt = header.checkpoints.get(&r.method).map_or("none", String::as_str);
        let _ = writeln!(
            s,
            ",{},{},{},{}",
            scale,
            csv_field(ckpt),
            csv_field(&header.text_encoder),
            csv_field(&header.data)
        );
    }
    s
}

pub(super) fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const COLUMNS: &[MetricColumn] = &[
        col("rmse", "RMSE", 1.0),
        pooled("jerk_pooled", "jerk", "jerk_gt", "jerk Σ/ΣGT"),
    ];
    const LAYOUT: Layout = Layout {
        title: "test",
        columns: COLUMNS,
        k_column: false,
    };

    fn record(item: usize, rmse: f64, jerk: f64, jerk_gt: f64) -> ClipRecord {
        ClipRecord {
            method: "vae".into(),
            placement: "all_frames".into(),
            k_extra: 0,
            seed: 0,
            item,
            clip_id: format!("clip{item}"),
            metrics: [("rmse", rmse), ("jerk", jerk), ("jerk_gt", jerk_gt)]
                .into_iter()
                .map(|(k, v)| (k.to_string(), v))
                .collect(),
        }
    }

    #[test]
    fn a_clip_without_the_pooled_quantity_is_left_out_of_both_sums_not_the_whole_cell() {
        let records = [
            record(0, 1.0, 2.0, 1.0),
            record(1, 3.0, f64::NAN, f64::NAN),
            record(2, 2.0, 4.0, 3.0),
        ];
        let rows = summarize(&records, &LAYOUT).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].clips, 3);
        assert!(
            (rows[0].values[0].mean - 2.0).abs() < 1e-12,
            "mean RMSE over all three clips"
        );
        assert!(
            (rows[0].values[1].mean - 1.5).abs() < 1e-12,
            "pooled (2 + 4) / (1 + 3), got {}",
            rows[0].values[1].mean
        );
        let none = summarize(&[record(0, 1.0, f64::NAN, 1.0)], &LAYOUT).unwrap();
        assert!(none[0].values[1].mean.is_nan(), "no clip with the quantity: no value");
    }
}
