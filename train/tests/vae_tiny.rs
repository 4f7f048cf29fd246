//! A short tiny frame-wise VAE run on procedural clips lowers its loss, writes latent statistics, and resumes
//! exactly (n steps + resume + n steps = 2n steps straight, bitwise on the CPU backend).

use std::path::Path;
use std::sync::Mutex;

use any4d_data::store::write_synth_with;
use any4d_data::synth::SynthConfig;
use any4d_model::frame_vae::FrameVae;
use any4d_train::backend::{Backend, Precision, device};
use any4d_train::config::Duration;
use any4d_train::loop_common::{LoopSetup, Outcome, StopFlag, train};
use any4d_train::progress::ProgressMode;
use any4d_train::run_folder::{METRICS_FILE, RunFolder, read_table};
use any4d_train::vae_loop::{
    LATENT_STATS_FILE, StoredLatentStats, VaeModelConfig, VaeObjective, VaeRunConfig, VaeRunOptions, train_vae,
};
use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::Tensor;

/// burn's CPU RNG seed is process-wide: tests that train run one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

fn store(dir: &Path) -> std::path::PathBuf {
    let out = dir.join("store");
    let cfg = SynthConfig {
        clips: 10,
        seed: 3,
        frames: 4,
        min_vertices: 256,
        max_vertices: 512,
    };
    write_synth_with(&cfg, &out, 32, None).expect("synthetic store");
    out
}

fn tiny(steps: u64) -> VaeRunConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/vae/tiny.toml");
    let mut cfg = VaeRunConfig::load(&path).expect("configs/vae/tiny.toml");
    cfg.train.duration = Duration::Steps(steps);
    cfg.train.batch_size = 4;
    cfg.train.micro_batch = 2;
    cfg.train.checkpoint_every = 5;
    cfg.train.valid_every = 5;
    cfg
}

fn params(m: &FrameVae) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0
                .extend(p.val().into_data().try_to_vec::<f32>().expect("f32 parameters"));
        }
    }
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

#[test]
fn tiny_vae_run_lowers_its_loss_and_stores_latent_stats() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = store(dir.path());
    let cfg = tiny(30);
    let opts = VaeRunOptions {
        data,
        runs_dir: dir.path().join("runs"),
        name: "vae".into(),
        progress: ProgressMode::Quiet,
        stop: StopFlag::new(),
    };
    let (run, outcome) = train_vae(&cfg, &opts).unwrap();
    assert!(matches!(outcome, Outcome::Finished { steps: 30, .. }), "{outcome:?}");
    let t = read_table(&run.path(METRICS_FILE)).unwrap();
    let loss = t.header.iter().position(|h| h == "loss").unwrap() - 1;
    let mean = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|r| r.1[loss]).sum::<f64>() / rows.len() as f64;
    let (first, last) = (mean(&t.rows[..5]), mean(&t.rows[25..]));
    assert!(
        last < 0.8 * first,
        "loss did not drop: first 5 steps {first}, last 5 {last}"
    );
    let stats: StoredLatentStats =
        serde_json::from_str(&std::fs::read_to_string(run.path(LATENT_STATS_FILE)).unwrap()).unwrap();
    assert_eq!(stats.step, 30);
    assert!(stats.stats.motion_std > 0.0 && stats.stats.shape_std > 0.0, "{stats:?}");
}

#[test]
fn tiny_vae_resume_is_bitwise_equal_to_straight_training() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = store(dir.path());
    let n = 3;
    let go = |run: &RunFolder, steps: u64, resume: Option<std::path::PathBuf>| {
        let cfg = tiny(steps);
        let VaeModelConfig::Framewise(m) = &cfg.model else {
            panic!("tiny is frame-wise")
        };
        let dev = device(Backend::Flex, Precision::F32).unwrap().autodiff();
        dev.seed(cfg.train.seed);
        let model = m.init(&dev);
        let objective = VaeObjective::<FrameVae>::new(&data, cfg.train.micro_batch).unwrap();
        let setup = LoopSetup {
            run,
            train: &cfg.train,
            optim: &cfg.optim,
            device: dev,
            stop: StopFlag::new(),
            progress: ProgressMode::Quiet,
            resume,
        };
        train(&objective, model, setup).unwrap()
    };
    let runs = dir.path().join("runs");
    let straight_run = RunFolder::create(&runs, "straight", "", &["rec", "kl"]).unwrap();
    let (straight, _) = go(&straight_run, 2 * n, None);
    let split_run = RunFolder::create(&runs, "split", "", &["rec", "kl"]).unwrap();
    let (_, first) = go(&split_run, n, None);
    let Outcome::Finished { checkpoint, .. } = first else {
        panic!("{first:?}")
    };
    let (resumed, _) = go(&split_run, 2 * n, Some(checkpoint));
    assert_eq!(
        params(&straight),
        params(&resumed),
        "resumed VAE differs from straight training"
    );
}
