//! P-Table 4 (docs/method.md §6.4): end-to-end seconds of every method (encode → sample → decode) on synthetic grid
//! meshes of 512…4096 vertices, 16 frames (one window) and 31 (the two-stage rollout), batch 1, median of the timed
//! runs after one warm-up.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use any4d_data::Clip;
use any4d_model::bench::median;

use super::long_horizon::generate_long;
use super::summary::{Layout, TableHeader, csv_field, header_lines};
use super::{TableOptions, TableReport, header_for, progress_bar, write_text};
use crate::rollout::{OverlapSource, RolloutSpec};

use crate::error::{EvalError, Result};

/// Title of P-Table 4 (its columns are vertex counts, not metrics).
pub const LAYOUT: Layout = Layout {
    title: "Table 4: end-to-end inference seconds (encode → sample → decode)",
    columns: &[],
    k_column: false,
};

/// Vertex counts of P-Table 4.
pub const PAPER_VERTICES: [usize; 4] = [512, 1024, 2048, 4096];
/// Frame counts of P-Table 4: one window, and the two-stage rollout.
pub const PAPER_FRAMES: [usize; 2] = [16, 31];
/// Timed runs per size (the median is reported; docs/method.md §6.4).
pub const PAPER_REPS: usize = 10;
/// Keyframes of a timed clip sit every this many frames, and on the last one.
const KEYFRAME_STRIDE: usize = 15;
/// Noise seed of every timed generation.
const SEED: u64 = 42;

/// The options of P-Table 4.
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// Vertex counts timed.
    pub vertices: Vec<usize>,
    /// Frame counts timed (≤ 16: one window; more: the rollout).
    pub frames: Vec<usize>,
    /// Timed repetitions after one warm-up.
    pub reps: usize,
    /// Reference of stage 2 for the long sequences.
    pub overlap_source: OverlapSource,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            vertices: PAPER_VERTICES.to_vec(),
            frames: PAPER_FRAMES.to_vec(),
            reps: PAPER_REPS,
            overlap_source: OverlapSource::GroundTruth,
        }
    }
}

/// A grid mesh with exactly `n` vertices (rows × cols, cols the largest divisor ≤ √n) waving over `frames` frames;
/// the input of the timing table (P-Table 4), in the normalised frame.
pub fn timing_clip(n: usize, frames: usize) -> Result<Clip> {
    let cols = (1..=((n as f64).sqrt() as usize))
        .rev()
        .find(|c| n.is_multiple_of(*c))
        .unwrap_or(1);
    let rows = n / cols;
    if rows < 2 || cols < 2 {
        return Err(EvalError::invalid(
            "timing",
            "vertices",
            format!("{n} vertices do not form a grid of at least 2 × 2"),
        ));
    }
    let mut faces = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let v = (r * cols + c) as u32;
            let (right, down) = (v + 1, v + cols as u32);
            faces.push([v, right, down]);
            faces.push([right, down + 1, down]);
        }
    }
    let vertices = (0..frames)
        .flat_map(|f| {
            (0..n).map(move |i| {
                let (x, y) = (
                    (i % cols) as f32 / (cols - 1) as f32 * 2.0 - 1.0,
                    (i / cols) as f32 / (rows - 1) as f32 * 2.0 - 1.0,
                );
                [x, y, 0.2 * (3.0 * x + 0.3 * f as f32).sin()]
            })
        })
        .collect();
    Clip::new(
        format!("timing_{n}x{frames}"),
        vertices,
        frames,
        n,
        faces,
        "a waving sheet",
        "timing",
    )
    .map_err(EvalError::from)
}

impl Timing {
    /// Runs the table: every method on [`timing_clip`]s of every size, one warm-up and `reps` timed runs each.
    pub fn run(&self, opts: &TableOptions) -> Result<TableReport> {
        super::refuse_oracle(&opts.methods, "table 4 (timing)")?;
        if opts.methods.is_empty() || self.reps == 0 {
            return Err(EvalError::invalid(
                "eval run",
                "methods",
                "table4 needs at least one method and one timed repetition",
            ));
        }
        let mut records = Vec::new();
        let total = opts.methods.len() * self.frames.len() * self.vertices.len();
        let bar = progress_bar(opts.progress, total, "timing")?;
        for method in &opts.methods {
            for &frames in &self.frames {
                for &n in &self.vertices {
                    let clip = timing_clip(n, frames)?;
                    let keyframes: Vec<usize> = (0..frames)
                        .step_by(KEYFRAME_STRIDE)
                        .chain([frames - 1])
                        .collect::<std::collections::BTreeSet<_>>()
                        .into_iter()
                        .collect();
                    let captions = vec![clip.caption.clone()];
                    let once = || -> Result<()> {
                        if frames <= RolloutSpec::paper().window {
                            method.complete(
                                &crate::methods::hide_non_keyframes(&clip, &keyframes),
                                &keyframes,
                                &clip.caption,
                                SEED,
                            )?;
                        } else {
                            generate_long(method.as_ref(), &clip, &keyframes, &captions, SEED, self.overlap_source)?;
                        }
                        Ok(())
                    };
                    once()?; // warm-up
                    let mut seconds = Vec::with_capacity(self.reps);
                    for _ in 0..self.reps {
                        let t = Instant::now();
                        once()?;
                        seconds.push(t.elapsed().as_secs_f64());
                    }
                    records.push(TimingRecord {
                        method: method.kind().label(),
                        frames,
                        vertices: n,
                        seconds,
                    });
                    bar.inc(1);
                }
            }
        }
        bar.finish_and_clear();
        let header = header_for(opts, Path::new("none (synthetic grid meshes)"));
        let (md, csv_text) = timing_tables(&records, &header);
        let mut files = Vec::new();
        write_text(&opts.out.join("summary.md"), &md, &mut files)?;
        write_text(&opts.out.join("summary.csv"), &csv_text, &mut files)?;
        Ok(TableReport {
            title: LAYOUT.title,
            rows: Vec::new(),
            markdown: md,
            files,
        })
    }
}

/// One P-Table 4 measurement: a method at one (frames, vertices) size, the timed repetitions in seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingRecord {
    pub method: String,
    pub frames: usize,
    pub vertices: usize,
    /// Seconds per timed run (the warm-up excluded).
    pub seconds: Vec<f64>,
}

/// P-Table 4 in Markdown and CSV: one row per (method, frames), one column per vertex count (median seconds), and
/// the mean over vertex counts.
pub fn timing_tables(records: &[TimingRecord], header: &TableHeader) -> (String, String) {
    let mut sizes: Vec<usize> = records.iter().map(|r| r.vertices).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let mut keys: Vec<(&str, usize)> = Vec::new();
    for r in records {
        if !keys.contains(&(r.method.as_str(), r.frames)) {
            keys.push((r.method.as_str(), r.frames));
        }
    }
    let reps = records.iter().map(|r| r.seconds.len()).max().unwrap_or(0);
    let mut md = header_lines(LAYOUT.title, header, 1);
    let _ = writeln!(md, "Median of {reps} timed runs after one warm-up, batch 1, seconds.\n");
    md.push_str("| Method | Frames |");
    let mut csv = String::from("method,frames");
    for n in &sizes {
        let _ = write!(md, " {n} |");
        let _ = write!(csv, ",v{n}");
    }
    md.push_str(" Mean |\n|---|---|");
    md.push_str(&"---|".repeat(sizes.len() + 1));
    md.push('\n');
    let _ = writeln!(csv, ",mean,device");
    for (method, frames) in keys {
        let meds: Vec<Option<f64>> = sizes
            .iter()
            .map(|&n| {
                records
                    .iter()
                    .find(|r| r.method == method && r.frames == frames && r.vertices == n)
                    .map(|r| median(&r.seconds))
            })
            .collect();
        let present: Vec<f64> = meds.iter().flatten().copied().collect();
        let mean = present.iter().sum::<f64>() / present.len().max(1) as f64;
        let _ = write!(md, "| {method} | {frames} |");
        let _ = write!(csv, "{},{frames}", csv_field(method));
        for m in &meds {
            let _ = write!(md, " {} |", m.map_or("–".into(), |x| format!("{x:.3}")));
            let _ = write!(csv, ",{}", m.map_or(String::new(), |x| format!("{x}")));
        }
        let _ = writeln!(md, " {mean:.3} |");
        let _ = writeln!(csv, ",{mean},{}", csv_field(&header.device));
    }
    (md, csv)
}
