//! One unit of import work (a source file or folder, or one procedural clip) and its run: in its own thread,
//! under [`formats::guard`] and a time limit, so that no single source can stop an import.

use std::path::PathBuf;
use std::sync::{Arc, mpsc};
use std::time::Duration;

use super::StoredClip;
use super::provenance::Provenance;
use crate::error::Result;
use crate::formats::skeletal::SkinStats;
use crate::formats::{self, Format};

/// What one source turned into: its clips (windows with their object uid), for a file with takes the takes
/// that failed (`source#take`, reason), and the skin-weight counts of the takes that were accepted. A source
/// that produced nothing is `Rejected`.
pub(super) enum Outcome {
    /// Windows with their object, the takes that failed (`source#take`, reason), skin statistics and the
    /// one-frame animations that are not takes (`source#name`).
    Clips(Vec<(StoredClip, String)>, Vec<(String, String)>, SkinStats, Vec<String>),
    Rejected(String),
}

/// One unit of work: a file or folder found under the sources, or one procedural clip.
#[derive(Clone)]
pub(super) enum Job {
    File {
        source: String,
        path: PathBuf,
        format: Result<Format>,
        provenance: Result<Provenance>,
    },
    Synth {
        source: String,
        index: usize,
    },
}

impl Job {
    pub(super) fn source(&self) -> &str {
        match self {
            Job::File { source, .. } | Job::Synth { source, .. } => source,
        }
    }

    pub(super) fn format_name(&self) -> &'static str {
        match self {
            Job::File { format: Ok(f), .. } => f.name(),
            Job::File { format: Err(_), .. } => "",
            Job::Synth { .. } => "synth",
        }
    }

    pub(super) fn provenance(&self) -> Provenance {
        match self {
            Job::File { provenance: Ok(p), .. } => p.clone(),
            _ => Provenance::default(),
        }
    }
}

/// The per-source work of an import or a synth run.
pub(super) type Process = Arc<dyn Fn(&Job) -> Outcome + Send + Sync>;

/// Stack of each reader thread: eight times what every reader's depth limit needs (the COLLADA parser at its
/// 512 levels fits Rust's default 2 MiB, tested), so that no file within the limits can overflow it.
const READER_STACK: usize = 16 << 20;

/// Run `process` on `job` in its own thread, so that neither a panic nor a source slower than `limit` stops the
/// import: both become a rejection. A thread past its limit is left to finish on its own.
pub(super) fn run_one(job: &Job, process: &Process, limit: Duration) -> Outcome {
    let (tx, rx) = mpsc::channel();
    let (job, process) = (job.clone(), Arc::clone(process));
    let spawned = std::thread::Builder::new()
        .name("any4d-import".into())
        .stack_size(READER_STACK)
        .spawn(move || {
            let source = PathBuf::from(job.source());
            let outcome = formats::guard(&source, || Ok(process(&job)))
                .unwrap_or_else(|e| Outcome::Rejected(format!("{}: {}", e.field, e.reason)));
            // The receiver is gone when the time limit passed; nothing is waiting for this result then.
            let _ = tx.send(outcome);
        });
    if let Err(e) = spawned {
        return Outcome::Rejected(format!("import: could not start a thread for this source: {e}"));
    }
    match rx.recv_timeout(limit) {
        Ok(outcome) => outcome,
        Err(mpsc::RecvTimeoutError::Timeout) => Outcome::Rejected(format!(
            "time limit: reading and preprocessing took more than {limit:?}; skipped"
        )),
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            Outcome::Rejected("import: the thread for this source ended without a result".into())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{CLIPS_FILE, StoreWriter};

    fn job(name: &str) -> Job {
        Job::File {
            source: format!("/src/{name}"),
            path: PathBuf::from(format!("/src/{name}")),
            format: Ok(Format::Bin),
            provenance: Ok(Provenance::default()),
        }
    }

    fn reason(outcome: Outcome) -> String {
        match outcome {
            Outcome::Rejected(r) => r,
            Outcome::Clips(c, ..) => panic!("{} clips, expected a rejection", c.len()),
        }
    }

    #[test]
    fn a_panicking_or_slow_source_is_rejected_and_the_rest_goes_on() {
        let process: Process = Arc::new(|job: &Job| match job.source() {
            "/src/panics.bin" => panic!("reader bug"),
            "/src/hangs.bin" => {
                std::thread::sleep(Duration::from_secs(30));
                Outcome::Rejected("finished".into())
            }
            _ => Outcome::Clips(Vec::new(), Vec::new(), SkinStats::default(), Vec::new()),
        });
        // Generous limits where the work is instant (a panic's backtrace can take a while on a busy machine).
        let generous = Duration::from_secs(120);
        let r = reason(run_one(&job("panics.bin"), &process, generous));
        assert!(r.starts_with("panic: ") && r.contains("reader bug"), "{r}");
        let r = reason(run_one(&job("hangs.bin"), &process, Duration::from_millis(200)));
        assert!(r.starts_with("time limit:"), "{r}");
        assert!(matches!(
            run_one(&job("fine.bin"), &process, generous),
            Outcome::Clips(..)
        ));
    }

    #[test]
    fn a_dropped_writer_removes_its_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join(CLIPS_FILE);
        let writer = StoreWriter::create(&dest, 16, 8).unwrap();
        assert!(dest.with_extension("bin.tmp").exists());
        drop(writer);
        assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
    }
}
