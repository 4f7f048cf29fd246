//! The real `any4d` binary interrupted mid-run, driven as a child process:
//! `kill -9` leaves a readable run folder that loses at most the step in progress and, resumed, ends with the
//! same parameters as an uninterrupted run; a new run with the same name never touches the killed run's folder;
//! Ctrl-C saves a checkpoint, exits with 130 and resumes to completion.
#![cfg(unix)]

mod common;

use std::collections::BTreeMap;
use std::fs::{self, File};
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread::sleep;
use std::time::{Duration, Instant};

use any4d_model::any_vae::AnyMeshVaeConfig;
use any4d_model::frame_vae::FrameVae;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::checkpoint;
use any4d_train::run_folder::{CHECKPOINTS_DIR, LOG_FILE, METRICS_FILE, RunFolder, Table, VALID_FILE, read_table};
use any4d_train::runs::{LoadedVae, load_vae_run};
use any4d_train::vae_loop::{LATENT_STATS_FILE, VaeRunConfig};
use common::fixtures::{params, synth_store, tiny_vae};
use tempfile::TempDir;

/// Optimiser steps of every run. A step takes about 0.1 s in a debug build, so a run killed after its second
/// checkpoint still has over a second of work left: the signal lands mid-way even on a loaded machine.
const STEPS: u64 = 16;
/// Longest wait for any one child event (a checkpoint, an exit), generous for a loaded 2-core CI machine.
const PATIENCE: Duration = Duration::from_secs(120);

/// A synthetic store and a tiny VAE config (one checkpoint per step) in a temporary folder.
struct Fixture {
    dir: TempDir,
    data: PathBuf,
    config: PathBuf,
    runs: PathBuf,
    cfg: VaeRunConfig,
}

impl Fixture {
    fn new() -> Self {
        let dir = tempfile::tempdir().expect("temporary folder");
        let data = synth_store(dir.path(), 3);
        let mut cfg = tiny_vae(STEPS);
        cfg.train.micro_batch = 2;
        cfg.train.checkpoint_every = 1;
        cfg.train.keep_last = 2;
        cfg.train.valid_every = STEPS;
        cfg.train.progress_every_secs = 3600.0;
        let config = dir.path().join("vae.toml");
        fs::write(&config, cfg.to_toml().expect("config as TOML")).expect("write the config");
        let runs = dir.path().join("runs");
        Fixture {
            dir,
            data,
            config,
            runs,
            cfg,
        }
    }

    /// `any4d train vae --config CFG --data STORE --runs-dir RUNS --run NAME`; `label` names its output files.
    fn train(&self, name: &str, label: &str) -> Launched {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_any4d"));
        cmd.args(["train", "vae", "--config"])
            .arg(&self.config)
            .arg("--data")
            .arg(&self.data)
            .arg("--runs-dir")
            .arg(&self.runs)
            .args(["--run", name]);
        self.launch(cmd, label)
    }

    /// `any4d train vae --resume RUN --data STORE --runs-dir RUNS`.
    fn resume(&self, run: &Path, label: &str) -> Launched {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_any4d"));
        cmd.args(["train", "vae", "--resume"])
            .arg(run)
            .arg("--data")
            .arg(&self.data)
            .arg("--runs-dir")
            .arg(&self.runs);
        self.launch(cmd, label)
    }

    /// Starts `cmd` with stdout and stderr in files (not a terminal, so the CLI prints compact lines, and no
    /// pipe that could fill up and block the child).
    fn launch(&self, mut cmd: Command, label: &str) -> Launched {
        let out = self.dir.path().join(format!("{label}.stdout"));
        let err = self.dir.path().join(format!("{label}.stderr"));
        cmd.stdin(Stdio::null())
            .stdout(File::create(&out).expect("stdout file"))
            .stderr(File::create(&err).expect("stderr file"));
        let child = cmd.spawn().expect("start the any4d binary");
        Launched {
            child,
            label: label.to_string(),
            out,
            err,
        }
    }

    /// The frame-wise VAE of the fixture's config, freshly initialised on the CPU.
    fn fresh_model(&self) -> FrameVae {
        let AnyMeshVaeConfig::Framewise(m) = &self.cfg.model else {
            panic!("configs/vae/tiny.toml is frame-wise")
        };
        m.init(&cpu())
    }
}

/// A running `any4d` child and the files holding its output.
struct Launched {
    child: Child,
    label: String,
    out: PathBuf,
    err: PathBuf,
}

impl Launched {
    fn stdout(&self) -> String {
        fs::read_to_string(&self.out).unwrap_or_else(|e| format!("<cannot read {}: {e}>", self.out.display()))
    }

    /// Both outputs, for failure messages.
    fn outputs(&self) -> String {
        let err =
            fs::read_to_string(&self.err).unwrap_or_else(|e| format!("<cannot read {}: {e}>", self.err.display()));
        format!("--- {} stdout ---\n{}--- stderr ---\n{err}", self.label, self.stdout())
    }

    /// Kills the child (if still running) and fails the test with `why` and its output.
    fn fail(&mut self, why: &str) -> ! {
        // Best effort: the child may have exited already; the test fails either way.
        let _ = self.child.kill();
        let _ = self.child.wait();
        panic!("{}: {why}\n{}", self.label, self.outputs())
    }

    fn try_wait(&mut self) -> Option<ExitStatus> {
        match self.child.try_wait() {
            Ok(s) => s,
            Err(e) => self.fail(&format!("cannot poll the child: {e}")),
        }
    }

    /// Waits for the child to exit, at most [`PATIENCE`].
    fn wait(&mut self) -> ExitStatus {
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.try_wait() {
                return status;
            }
            if t0.elapsed() > PATIENCE {
                self.fail(&format!("still running after {PATIENCE:?}"));
            }
            sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the child to exit with status 0 and returns its stdout.
    fn succeed(&mut self) -> String {
        let status = self.wait();
        if !status.success() {
            self.fail(&format!("expected success, got {status}"));
        }
        self.stdout()
    }

    /// Polls until a complete checkpoint of step ≥ `min_step` exists under `ckpts` and returns its step; fails if
    /// the child exits first or nothing appears within [`PATIENCE`].
    fn wait_for_checkpoint(&mut self, ckpts: &Path, min_step: u64) -> u64 {
        let t0 = Instant::now();
        loop {
            if let Some(status) = self.try_wait() {
                self.fail(&format!("exited ({status}) before writing checkpoint step {min_step}"));
            }
            if ckpts.is_dir() {
                // The child writes and prunes concurrently: a listing error is retried, not fatal.
                if let Ok(list) = checkpoint::list(ckpts)
                    && let Some(&(step, _)) = list.last()
                    && step >= min_step
                {
                    return step;
                }
            }
            if t0.elapsed() > PATIENCE {
                self.fail(&format!(
                    "no complete checkpoint of step ≥ {min_step} in {} after {PATIENCE:?}",
                    ckpts.display()
                ));
            }
            sleep(Duration::from_millis(5));
        }
    }
}

fn cpu() -> burn::prelude::Device {
    device(Backend::Flex, Precision::F32).expect("CPU device")
}

fn frame_vae(vae: &LoadedVae) -> &FrameVae {
    vae.frame_vae().expect("a frame-wise VAE run")
}

/// Every file under `root` (relative path → bytes) and every folder (→ empty), to show a folder is untouched.
fn snapshot(root: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Option<Vec<u8>>>) {
        for entry in fs::read_dir(dir).unwrap_or_else(|e| panic!("list {}: {e}", dir.display())) {
            let path = entry.expect("folder entry").path();
            let rel = path.strip_prefix(root).expect("under root").to_path_buf();
            if path.is_dir() {
                out.insert(rel, None);
                walk(root, &path, out);
            } else {
                let bytes = fs::read(&path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()));
                out.insert(rel, Some(bytes));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(root, root, &mut out);
    out
}

/// The deterministic columns of `metrics.csv` (loss terms, loss, lr, grad_norm; not the throughput) per step.
fn losses(table: &Table) -> Vec<(u64, Vec<f64>)> {
    let keep: Vec<usize> = table.header[1..]
        .iter()
        .enumerate()
        .filter(|(_, h)| !h.ends_with("_per_s"))
        .map(|(i, _)| i)
        .collect();
    assert!(keep.len() >= 3, "metrics.csv header {:?}", table.header);
    table
        .rows
        .iter()
        .map(|(step, v)| (*step, keep.iter().map(|&i| v[i]).collect()))
        .collect()
}

#[test]
fn kill_9_loses_at_most_one_step_keeps_the_folder_and_resumes_to_the_uninterrupted_parameters() {
    let fx = Fixture::new();

    // A run killed with SIGKILL after its second checkpoint, i.e. somewhere in a later step or checkpoint write.
    let mut killed = fx.train("killed", "killed");
    let killed_dir = fx.runs.join("killed-1");
    let ckpts = killed_dir.join(CHECKPOINTS_DIR);
    killed.wait_for_checkpoint(&ckpts, 2);
    if let Err(e) = killed.child.kill() {
        killed.fail(&format!("SIGKILL failed: {e}"));
    }
    let status = killed.wait();
    if status.signal() != Some(9) {
        killed.fail(&format!(
            "the run ended ({status}) before SIGKILL reached it; the test needs more steps to kill it mid-way"
        ));
    }

    // The folder stays readable, and the newest complete checkpoint is at most one step behind the metrics.
    RunFolder::open(&killed_dir).expect("a killed run's folder opens");
    let metrics = read_table(&killed_dir.join(METRICS_FILE)).expect("metrics.csv of a killed run parses");
    read_table(&killed_dir.join(VALID_FILE)).expect("valid.csv of a killed run parses");
    let ckpt = checkpoint::latest(&ckpts)
        .expect("list checkpoints")
        .expect("a complete checkpoint survives kill -9");
    let saved = checkpoint::read_state(&ckpt)
        .expect("state.json of the newest checkpoint")
        .step;
    let logged = metrics.rows.last().map_or(0, |r| r.0);
    assert!(
        (2..STEPS).contains(&saved),
        "newest checkpoint is step {saved}, expected a mid-way step in 2..{STEPS}"
    );
    assert!(
        logged == saved || logged == saved + 1,
        "kill -9 with checkpoint_every = 1 lost more than the step in progress: metrics.csv reaches step \
         {logged}, the newest checkpoint is step {saved}"
    );
    eprintln!("kill -9 landed after metrics step {logged}, newest checkpoint step {saved} of {STEPS}");
    let steps: Vec<u64> = metrics.rows.iter().map(|r| r.0).collect();
    assert_eq!(
        steps,
        (1..=logged).collect::<Vec<_>>(),
        "metrics.csv steps of the killed run"
    );
    checkpoint::load_model(fx.fresh_model(), &ckpt).expect("the newest checkpoint of a killed run loads");
    assert!(
        !killed_dir.join(LATENT_STATS_FILE).exists(),
        "a killed run must not have final latent statistics"
    );

    // An uninterrupted run under the same name claims a new folder and leaves the killed one as it was.
    let before = snapshot(&killed_dir);
    let mut straight = fx.train("killed", "straight");
    let out = straight.succeed();
    let straight_dir = fx.runs.join("killed-2");
    assert!(
        out.contains(&format!("run folder: {}", straight_dir.display())),
        "a second run named `killed` should go to {}\n{}",
        straight_dir.display(),
        straight.outputs()
    );
    assert!(
        snapshot(&killed_dir) == before,
        "starting a run with the same name changed the killed run's folder {}",
        killed_dir.display()
    );

    // The killed run resumes from its newest checkpoint and finishes.
    let mut resumed = fx.resume(&killed_dir, "resumed");
    let out = resumed.succeed();
    assert!(
        out.contains(&format!("finished {STEPS} steps")),
        "resume should finish all {STEPS} steps\n{}",
        resumed.outputs()
    );
    let log = fs::read_to_string(killed_dir.join(LOG_FILE)).expect("log.txt");
    assert!(
        log.contains(&format!("at step {saved}")),
        "the resume should start from step {saved}; log.txt:\n{log}"
    );

    // Same final parameters, latent statistics and per-step losses as the uninterrupted run. The CPU backend is
    // deterministic and every random stream is restored from the checkpoint, so equality is exact.
    let dev = cpu();
    let a = load_vae_run(&straight_dir, &dev).expect("load the uninterrupted run");
    let b = load_vae_run(&killed_dir, &dev).expect("load the killed-and-resumed run");
    assert_eq!((a.step, b.step), (STEPS, STEPS), "final checkpoint steps");
    let (pa, pb) = (params(frame_vae(&a)), params(frame_vae(&b)));
    assert_eq!(pa.len(), pb.len(), "parameter counts");
    let differ = pa.iter().zip(&pb).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
    assert_eq!(
        differ,
        0,
        "{differ} of {} parameters differ between the uninterrupted and the killed-and-resumed run",
        pa.len()
    );
    assert_eq!(a.stats, b.stats, "latent statistics differ");
    let table = |dir: &Path| read_table(&dir.join(METRICS_FILE)).expect("metrics.csv");
    assert_eq!(
        losses(&table(&straight_dir)),
        losses(&table(&killed_dir)),
        "per-step losses differ (the killed run's repeated step keeps its resumed row)"
    );
}

#[test]
fn ctrl_c_saves_a_checkpoint_exits_130_and_resumes() {
    let fx = Fixture::new();
    let mut run = fx.train("stopped", "ctrl-c");
    let dir = fx.runs.join("stopped-1");
    let ckpts = dir.join(CHECKPOINTS_DIR);
    run.wait_for_checkpoint(&ckpts, 1);
    let pid = run.child.id().to_string();
    match Command::new("kill").args(["-INT", &pid]).status() {
        Ok(s) if s.success() => {}
        other => run.fail(&format!("`kill -INT {pid}` failed: {other:?}")),
    }
    let status = run.wait();
    if status.code() != Some(130) {
        run.fail(&format!("Ctrl-C should exit with 130, got {status}"));
    }
    let out = run.stdout();
    let Some(step) = out
        .lines()
        .find_map(|l| l.strip_prefix("interrupted after step "))
        .and_then(|rest| rest.split(';').next())
        .and_then(|s| s.parse::<u64>().ok())
    else {
        run.fail("stdout does not say `interrupted after step N`")
    };
    assert!(
        (1..STEPS).contains(&step),
        "interrupted at step {step}, expected 1..{STEPS}"
    );

    // Ctrl-C loses nothing: the checkpoint it saved is the newest and matches the last metrics row.
    let ckpt = checkpoint::latest(&ckpts).expect("list").expect("a checkpoint");
    let saved = checkpoint::read_state(&ckpt).expect("state.json").step;
    assert_eq!(
        saved,
        step,
        "the newest checkpoint {} is not the interrupted step",
        ckpt.display()
    );
    let metrics = read_table(&dir.join(METRICS_FILE)).expect("metrics.csv of an interrupted run parses");
    assert_eq!(metrics.rows.last().map(|r| r.0), Some(step), "last metrics row");
    let log = fs::read_to_string(dir.join(LOG_FILE)).expect("log.txt");
    assert!(log.contains("stopped by request"), "log.txt:\n{log}");

    let mut resumed = fx.resume(&dir, "ctrl-c-resumed");
    let out = resumed.succeed();
    assert!(
        out.contains(&format!("finished {STEPS} steps")),
        "resume should finish all {STEPS} steps\n{}",
        resumed.outputs()
    );
    let vae = load_vae_run(&dir, &cpu()).expect("the resumed run loads with its latent statistics");
    assert_eq!(vae.step, STEPS);
    let steps: Vec<u64> = read_table(&dir.join(METRICS_FILE))
        .expect("metrics.csv")
        .rows
        .iter()
        .map(|r| r.0)
        .collect();
    assert_eq!(steps, (1..=STEPS).collect::<Vec<_>>(), "metrics.csv steps after resume");
}
