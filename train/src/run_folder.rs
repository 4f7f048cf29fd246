//! Append-only run folders : `runs/<name>-<n>/` with the resolved `config.toml`, `log.txt`,
//! `metrics.csv`, `valid.csv`, `checkpoints/` and, for an RF run that samples during validation, `samples.csv`. A
//! folder is claimed with `create_dir` (never reused), files that are replaced are written atomically (temp file +
//! rename), logs and tables are only appended to.

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use any4d_data::io::write_atomic;

use crate::error::{Result, TrainError, io_err};

/// File names inside a run folder.
pub const CONFIG_FILE: &str = "config.toml";
/// Human-readable log, one line per event.
pub const LOG_FILE: &str = "log.txt";
/// One row per optimiser step.
pub const METRICS_FILE: &str = "metrics.csv";
/// One row per validation.
pub const VALID_FILE: &str = "valid.csv";
/// One row per validation-sampling round of an RF run: `step, rmse, chamfer, dtw`.
pub const SAMPLES_FILE: &str = "samples.csv";
/// Loss-curve plot written at the end of a run.
pub const PLOT_FILE: &str = "loss.png";
/// Folder of `step_N/` checkpoints.
pub const CHECKPOINTS_DIR: &str = "checkpoints";

/// Columns of `metrics.csv` that follow the loss terms.
pub const METRIC_TAIL: [&str; 5] = ["loss", "lr", "grad_norm", "steps_per_s", "samples_per_s"];

/// An open run folder.
#[derive(Debug, Clone)]
pub struct RunFolder {
    root: PathBuf,
}

impl RunFolder {
    /// Claims `runs_dir/<name>-<n>` with the smallest free n ≥ 1 and writes `config.toml`, `log.txt`, and the
    /// CSV headers (`step, <terms…>, loss, lr, grad_norm, steps_per_s, samples_per_s`; `valid.csv`:
    /// `step, <terms…>, loss`). Never touches an existing folder.
    pub fn create(runs_dir: &Path, name: &str, resolved_config: &str, terms: &[&str]) -> Result<Self> {
        if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
            return Err(TrainError::Config {
                path: runs_dir.to_path_buf(),
                reason: format!("run name `{name}` must be non-empty, without path separators or a leading dot"),
            });
        }
        fs::create_dir_all(runs_dir).map_err(io_err("create runs folder", runs_dir))?;
        let root = (1..)
            .map(|n| runs_dir.join(format!("{name}-{n}")))
            .find_map(|candidate| match fs::create_dir(&candidate) {
                Ok(()) => Some(Ok(candidate)),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => None,
                Err(e) => Some(Err(TrainError::Io {
                    op: "create run folder",
                    path: candidate,
                    source: e,
                })),
            })
            .expect("an unbounded range always yields a candidate")?;
        let run = RunFolder { root };
        write_atomic(&run.path(CONFIG_FILE), resolved_config.as_bytes())?;
        fs::create_dir(run.path(CHECKPOINTS_DIR)).map_err(io_err("create", run.path(CHECKPOINTS_DIR)))?;
        let header = |tail: &[&str]| {
            let mut cols = vec!["step"];
            cols.extend_from_slice(terms);
            cols.extend_from_slice(tail);
            cols.join(",") + "\n"
        };
        write_atomic(&run.path(METRICS_FILE), header(&METRIC_TAIL).as_bytes())?;
        write_atomic(&run.path(VALID_FILE), header(&["loss"]).as_bytes())?;
        write_atomic(&run.path(LOG_FILE), b"")?;
        Ok(run)
    }

    /// Opens an existing run folder (for `--resume`); it must hold `config.toml` and `checkpoints/`.
    pub fn open(root: &Path) -> Result<Self> {
        for needed in [CONFIG_FILE, CHECKPOINTS_DIR, METRICS_FILE] {
            let p = root.join(needed);
            if !p.exists() {
                return Err(TrainError::Checkpoint {
                    path: root.to_path_buf(),
                    reason: format!("not a run folder: `{needed}` is missing"),
                });
            }
        }
        Ok(RunFolder {
            root: root.to_path_buf(),
        })
    }

    /// The folder itself.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// A path inside the folder.
    pub fn path(&self, file: &str) -> PathBuf {
        self.root.join(file)
    }

    /// The resolved config text.
    pub fn config_text(&self) -> Result<String> {
        let p = self.path(CONFIG_FILE);
        fs::read_to_string(&p).map_err(io_err("read", p))
    }

    /// Appends a line to `log.txt` (with a Unix-time prefix).
    pub fn log(&self, line: &str) -> Result<()> {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        self.append(LOG_FILE, &format!("[{secs}] {line}\n"))
    }

    /// Appends one row to `metrics.csv` (values in header order).
    pub fn append_metrics(&self, step: u64, values: &[f64]) -> Result<()> {
        self.append(METRICS_FILE, &csv_row(step, values))
    }

    /// Appends one row to `valid.csv` (values in header order).
    pub fn append_valid(&self, step: u64, values: &[f64]) -> Result<()> {
        self.append(VALID_FILE, &csv_row(step, values))
    }

    /// Creates `file` with the CSV header `step, <columns…>` unless it exists (a resumed run keeps appending).
    pub fn ensure_table(&self, file: &str, columns: &[&str]) -> Result<()> {
        let p = self.path(file);
        if p.exists() {
            return Ok(());
        }
        let mut cols = vec!["step"];
        cols.extend_from_slice(columns);
        Ok(write_atomic(&p, (cols.join(",") + "\n").as_bytes())?)
    }

    /// Appends one row to `samples.csv` (create it first with [`RunFolder::ensure_table`]).
    pub fn append_samples(&self, step: u64, values: &[f64]) -> Result<()> {
        self.append(SAMPLES_FILE, &csv_row(step, values))
    }

    fn append(&self, file: &str, text: &str) -> Result<()> {
        let p = self.path(file);
        let mut f = OpenOptions::new()
            .append(true)
            .open(&p)
            .map_err(io_err("open for append", &p))?;
        f.write_all(text.as_bytes()).map_err(io_err("append to", &p))
    }
}

fn csv_row(step: u64, values: &[f64]) -> String {
    let mut row = step.to_string();
    for v in values {
        row.push(',');
        row.push_str(&format!("{v:.7e}"));
    }
    row.push('\n');
    row
}

/// A parsed CSV table of a run (`metrics.csv` or `valid.csv`): header and rows. When a resumed run repeated
/// steps, the last row of a step wins.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column names, `step` first.
    pub header: Vec<String>,
    /// Rows: (step, the other columns).
    pub rows: Vec<(u64, Vec<f64>)>,
}

/// Reads a run CSV (for plots and tests).
pub fn read_table(path: &Path) -> Result<Table> {
    let text = fs::read_to_string(path).map_err(io_err("read", path))?;
    let bad = |line: usize, reason: String| TrainError::Checkpoint {
        path: path.to_path_buf(),
        reason: format!("line {line}: {reason}"),
    };
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| bad(1, "empty file".into()))?
        .split(',')
        .map(str::to_string)
        .collect();
    let mut rows: Vec<(u64, Vec<f64>)> = Vec::new();
    for (i, line) in lines.enumerate() {
        let mut fields = line.split(',');
        let step = fields
            .next()
            .and_then(|s| s.parse::<u64>().ok())
            .ok_or_else(|| bad(i + 2, format!("bad step in `{line}`")))?;
        let values = fields
            .map(|f| f.parse::<f64>().map_err(|e| bad(i + 2, format!("`{f}`: {e}"))))
            .collect::<Result<Vec<_>>>()?;
        if values.len() + 1 != header.len() {
            return Err(bad(
                i + 2,
                format!("{} columns, header has {}", values.len() + 1, header.len()),
            ));
        }
        rows.retain(|(s, _)| *s < step);
        rows.push((step, values));
    }
    Ok(Table { header, rows })
}

/// Opens `run_dir` to continue it: the run folder, its stored config read by `parse` (with `backend`, when given,
/// replacing the `[device] backend` that `device` points at), and its newest complete checkpoint.
pub fn open_for_resume<C>(
    run_dir: &Path,
    parse: impl FnOnce(&str, &Path) -> Result<C>,
    backend: Option<crate::backend::Backend>,
    device: impl FnOnce(&mut C) -> &mut crate::config::DeviceConfig,
) -> Result<(RunFolder, C, PathBuf)> {
    let run = RunFolder::open(run_dir)?;
    let mut cfg = parse(&run.config_text()?, &run.path(CONFIG_FILE))?;
    if let Some(b) = backend {
        device(&mut cfg).backend = b;
    }
    let ckpt = crate::checkpoint::latest(&run.path(CHECKPOINTS_DIR))?.ok_or_else(|| TrainError::Checkpoint {
        path: run_dir.to_path_buf(),
        reason: "no complete checkpoint to resume".into(),
    })?;
    Ok((run, cfg, ckpt))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_names_are_never_reused_and_files_exist() {
        let dir = tempfile::tempdir().unwrap();
        let a = RunFolder::create(dir.path(), "vae", "x = 1\n", &["rec", "kl"]).unwrap();
        let b = RunFolder::create(dir.path(), "vae", "x = 2\n", &["rec", "kl"]).unwrap();
        assert!(a.root().ends_with("vae-1") && b.root().ends_with("vae-2"));
        assert_eq!(a.config_text().unwrap(), "x = 1\n");
        a.append_metrics(1, &[0.5, 0.25, 0.75, 1e-4, 1.0, 2.0, 3.0]).unwrap();
        a.append_metrics(2, &[0.4, 0.25, 0.65, 1e-4, 1.0, 2.0, 3.0]).unwrap();
        let t = read_table(&a.path(METRICS_FILE)).unwrap();
        assert_eq!(t.header[..4], ["step", "rec", "kl", "loss"]);
        assert_eq!(t.rows.len(), 2);
        assert!((t.rows[1].1[2] - 0.65).abs() < 1e-9);
        assert!(RunFolder::create(dir.path(), "../x", "", &[]).is_err());
    }

    #[test]
    fn samples_table_is_created_once() {
        let dir = tempfile::tempdir().unwrap();
        let a = RunFolder::create(dir.path(), "r", "", &["x"]).unwrap();
        assert!(!a.path(SAMPLES_FILE).exists());
        a.ensure_table(SAMPLES_FILE, &["rmse", "chamfer", "dtw"]).unwrap();
        a.append_samples(5, &[0.5, 0.25, 0.125]).unwrap();
        a.ensure_table(SAMPLES_FILE, &["rmse", "chamfer", "dtw"]).unwrap();
        let t = read_table(&a.path(SAMPLES_FILE)).unwrap();
        assert_eq!(t.header, ["step", "rmse", "chamfer", "dtw"]);
        assert_eq!(t.rows, vec![(5, vec![0.5, 0.25, 0.125])]);
    }

    #[test]
    fn repeated_steps_after_resume_keep_the_last_row() {
        let dir = tempfile::tempdir().unwrap();
        let a = RunFolder::create(dir.path(), "r", "", &[]).unwrap();
        for (s, v) in [(1, 1.0), (2, 2.0), (3, 3.0), (2, 20.0), (3, 30.0)] {
            a.append_metrics(s, &[v, 0.0, 0.0, 0.0, 0.0]).unwrap();
        }
        let t = read_table(&a.path(METRICS_FILE)).unwrap();
        let losses: Vec<f64> = t.rows.iter().map(|r| r.1[0]).collect();
        assert_eq!(losses, [1.0, 20.0, 30.0]);
    }
}
