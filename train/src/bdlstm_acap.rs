//! `any4d train bdlstm --variant acap`: the faithful BD-LSTM (docs/method.md §5.3, "ACAP variant") on a store of
//! one fixed topology. Each frame is the per-vertex ACAP feature `[N, 9]` of its vertices against one reference
//! mesh (frame 0 of the first TRAIN clip), scaled to [−0.95, 0.95] by ranges fitted on the TRAIN clips; the codec
//! is the mesh-convolution encoder/decoder on the reference's one-ring graph. The run folder records the reference
//! mesh and the scaling (`acap.json`) so that completion needs neither the store nor a refit.

use std::path::{Path, PathBuf};

use any4d_data::Clip;
use any4d_data::acap::{ACAP_CHANNELS, AcapFrame, AcapScaling, AcapTopology, ScalingGranularity, check_topology};
use any4d_data::io::write_atomic;
use any4d_data::store::{Split, Store};
use any4d_model::bdlstm::{BdLstm, MeshConvCodec, MeshGraph};
use any4d_model::mesh_vae::Posterior;
use burn::prelude::{Device, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::bdlstm_loop::{
    BDLSTM_TERMS, BdlstmRunConfig, BdlstmRunOptions, BdlstmVariant, chain_losses, read_bdlstm_config, validate_chunks,
};
use crate::data_order::WholeClips;
use crate::devices::run_devices;
use crate::error::{Result, TrainError, io_err, run_err};
use crate::loop_common::{self, LoopSetup, Losses, Objective, Outcome, RunOptions};
use crate::run_folder::RunFolder;
use crate::runs;

/// The run file holding the reference mesh and the feature scaling.
pub const ACAP_FILE: &str = "acap.json";

/// Everything besides the weights that maps vertices to the network's features and back: `acap.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AcapRecord {
    /// Id of the store clip whose frame 0 is the reference.
    pub reference_clip: String,
    /// The reference mesh's vertices `[N]` (normalised store coordinates).
    pub reference: Vec<[f32; 3]>,
    /// The fixed topology's triangles.
    pub faces: Vec<[u32; 3]>,
    /// Fitted on every frame of the TRAIN clips.
    pub scaling: AcapScaling,
}

impl AcapRecord {
    /// The topology of the reference mesh (weights, graph, factorised solvers).
    pub fn topology(&self) -> Result<AcapTopology> {
        Ok(AcapTopology::new(&self.reference_clip, &self.reference, &self.faces)?)
    }

    /// [`AcapRecord::topology`] of the record read from the run in `run`, errors naming the run.
    pub fn topology_of_run(&self, run: &Path) -> Result<AcapTopology> {
        self.topology()
            .map_err(|e| run_err(run, format!("the reference mesh of `{ACAP_FILE}`: {e}")))
    }

    /// Writes `acap.json` into `run`.
    pub fn write(&self, run: &RunFolder) -> Result<()> {
        let json = serde_json::to_vec(self).map_err(|e| run_err(run.root(), format!("serialise {ACAP_FILE}: {e}")))?;
        Ok(write_atomic(&run.path(ACAP_FILE), &json)?)
    }

    /// Reads `acap.json` of the run in `run_dir` and checks that its parts agree.
    pub fn read(run_dir: &Path) -> Result<Self> {
        let path = run_dir.join(ACAP_FILE);
        if !path.is_file() {
            return Err(run_err(
                run_dir,
                format!("no `{ACAP_FILE}` (not a BD-LSTM run of the ACAP variant?)"),
            ));
        }
        let text = std::fs::read_to_string(&path).map_err(io_err("read", &path))?;
        let record: AcapRecord =
            serde_json::from_str(&text).map_err(|e| run_err(run_dir, format!("bad `{ACAP_FILE}`: {e}")))?;
        let bad = |reason: String| run_err(run_dir, format!("bad `{ACAP_FILE}`: {reason}"));
        let n = record.reference.len();
        let rows = record.scaling.mid.len();
        let want = match record.scaling.granularity {
            ScalingGranularity::PerChannel => 1,
            ScalingGranularity::PerVertexChannel => n,
        };
        if n == 0 {
            return Err(bad("the reference mesh has no vertices".into()));
        }
        if rows != want || record.scaling.half.len() != rows {
            return Err(bad(format!(
                "{rows} / {} scaling rows (mid / half), {want} expected for {:?} ranges of a {n}-vertex reference",
                record.scaling.half.len(),
                record.scaling.granularity
            )));
        }
        let finite = |rows: &[[f32; ACAP_CHANNELS]]| rows.iter().flatten().all(|v| v.is_finite());
        if !finite(&record.scaling.mid) || !record.scaling.half.iter().flatten().all(|&h| h.is_finite() && h > 0.0) {
            return Err(bad("scaling values must be finite, half-widths positive".into()));
        }
        if let Some(f) = record.faces.iter().find(|f| f.iter().any(|&v| v as usize >= n)) {
            return Err(bad(format!("triangle {f:?} indexes past the {n} reference vertices")));
        }
        Ok(record)
    }
}

/// Scaled ACAP features of every clip of one split, `[T · N · 9]` each.
struct FeatureSet {
    clips: Vec<Vec<f32>>,
}

impl FeatureSet {
    fn bytes(&self) -> usize {
        self.clips.iter().map(|c| c.len() * 4).sum()
    }
}

/// The ACAP BD-LSTM objective: scaled features of the TRAIN and VAL clips in host memory; terms (B1), (B2), KL
/// and Σw².
pub struct AcapObjective {
    cfg: BdlstmRunConfig,
    record: AcapRecord,
    edges: Vec<[u32; 2]>,
    frames: usize,
    train: FeatureSet,
    valid: FeatureSet,
    train_clips: WholeClips,
}

impl AcapObjective {
    /// Reads every clip of the store at `data`, checks that they share one topology, and computes their features.
    /// A new run fits the reference and scaling (`record` `None`); a resumed one reuses its `acap.json`.
    pub fn new(cfg: &BdlstmRunConfig, data: &Path, record: Option<AcapRecord>) -> Result<Self> {
        let store = Store::open(data)?;
        if store.frames() < cfg.bdlstm.min_window {
            return Err(TrainError::Setup(format!(
                "the store {} holds {}-frame clips, shorter than bdlstm.min_window = {}",
                data.display(),
                store.frames(),
                cfg.bdlstm.min_window
            )));
        }
        let (train_idx, valid_idx) = (store.indices(Split::Train), store.indices(Split::Val));
        let read =
            |indices: &[usize]| -> Result<Vec<Clip>> { indices.iter().map(|&i| Ok(store.get(i)?.clip)).collect() };
        let (train_clips, valid_clips) = (read(&train_idx)?, read(&valid_idx)?);
        let Some(first) = train_clips.first() else {
            return Err(TrainError::Setup(format!(
                "the store {} has no TRAIN clip",
                data.display()
            )));
        };
        let (name, n, faces) = match &record {
            Some(r) => (r.reference_clip.clone(), r.reference.len(), r.faces.clone()),
            None => (first.id.clone(), first.n_vertices, first.faces.clone()),
        };
        for clip in train_clips.iter().chain(&valid_clips) {
            check_topology(&name, n, &faces, clip)?;
        }
        let topology = match &record {
            Some(r) => r.topology()?,
            None => AcapTopology::new(&first.id, &first.vertices[..n], &first.faces)?,
        };
        let raw = |clips: &[Clip]| -> Result<Vec<Vec<AcapFrame>>> {
            clips
                .iter()
                .map(|c| {
                    let frames: Vec<&[[f32; 3]]> = c.vertices.chunks_exact(n).collect();
                    Ok(topology.features(&frames)?)
                })
                .collect()
        };
        let train_raw = raw(&train_clips)?;
        let record = match record {
            Some(r) => r,
            None => {
                let all: Vec<AcapFrame> = train_raw.iter().flatten().cloned().collect();
                AcapRecord {
                    reference_clip: first.id.clone(),
                    reference: first.vertices[..n].to_vec(),
                    faces: first.faces.clone(),
                    scaling: AcapScaling::fit(&all, cfg.bdlstm.acap_scaling)?,
                }
            }
        };
        let scale = |clips: Vec<Vec<AcapFrame>>| -> Result<FeatureSet> {
            let clips = clips
                .into_iter()
                .map(|frames| {
                    let mut flat = Vec::with_capacity(frames.len() * n * ACAP_CHANNELS);
                    for f in &frames {
                        flat.extend(record.scaling.scale(f)?.into_iter().flatten());
                    }
                    Ok(flat)
                })
                .collect::<Result<Vec<_>>>()?;
            Ok(FeatureSet { clips })
        };
        let train = scale(train_raw)?;
        let valid = scale(raw(&valid_clips)?)?;
        let train_groups = WholeClips::new(store.whole_clips(&train_idx)?);
        Ok(Self {
            cfg: cfg.clone(),
            edges: topology.edges(),
            record,
            frames: store.frames(),
            train,
            valid,
            train_clips: train_groups,
        })
    }

    /// The reference mesh and scaling the features use.
    pub fn record(&self) -> &AcapRecord {
        &self.record
    }

    /// Vertices N of the fixed topology.
    pub fn vertices(&self) -> usize {
        self.record.reference.len()
    }

    /// Number of VAL clips.
    pub fn valid_len(&self) -> usize {
        self.valid.clips.len()
    }

    /// Host bytes of the cached features.
    pub fn cached_bytes(&self) -> usize {
        self.train.bytes() + self.valid.bytes()
    }

    /// Features of frames `start..start + n` of each listed clip of `set`, `[B, n, N, 9]`.
    fn window(&self, set: &FeatureSet, clips: &[usize], starts: &[usize], n: usize, device: &Device) -> Tensor<4> {
        let frame = self.vertices() * ACAP_CHANNELS;
        let mut values = Vec::with_capacity(clips.len() * n * frame);
        for (&c, &s) in clips.iter().zip(starts) {
            values.extend_from_slice(&set.clips[c][s * frame..(s + n) * frame]);
        }
        Tensor::from_data(
            TensorData::new(values, [clips.len(), n, self.vertices(), ACAP_CHANNELS]),
            device,
        )
    }

    fn losses(&self, model: &BdLstm<MeshConvCodec>, window: Tensor<4>, posterior: Posterior) -> Result<Losses> {
        let graph = MeshGraph::new(&self.edges, self.vertices(), &window.device())
            .map_err(|e| TrainError::Setup(format!("ACAP mesh graph: {e}")))?;
        Ok(chain_losses(model, window, &graph, posterior, &self.cfg.loss_config()))
    }
}

impl Objective for AcapObjective {
    type Model = BdLstm<MeshConvCodec>;

    fn terms(&self) -> Vec<String> {
        BDLSTM_TERMS.iter().map(|s| s.to_string()).collect()
    }

    fn train_len(&self) -> usize {
        self.train_clips.len()
    }

    /// One window length n ~ U{min_window..=max_window} per batch, one start per clip.
    fn loss(&self, model: &Self::Model, indices: &[usize], rng: &mut ChaCha8Rng, device: &Device) -> Result<Losses> {
        let clips = self.train_clips.draw(indices, rng);
        let (n, starts) = self.cfg.draw_window(self.frames, clips.len(), rng);
        let window = self.window(&self.train, &clips, &starts, n, device);
        self.losses(model, window, Posterior::Sample)
    }

    /// (B3) and its terms on every VAL clip's whole window (posterior means, nominal initial states).
    fn validate(&self, model: &Self::Model, device: &Device, _step: u64) -> Result<Option<Vec<f64>>> {
        device.seed(loop_common::step_seed(self.cfg.train.seed, u64::MAX));
        validate_chunks(self.valid_len(), self.cfg.train.micro_batch, |chunk| {
            let starts = vec![0; chunk.len()];
            let window = self.window(&self.valid, chunk, &starts, self.frames, device);
            self.losses(model, window, Posterior::Mean)
        })
    }
}

/// Starts a new ACAP BD-LSTM run: the store's features and the fitted scaling are computed before the run folder
/// is claimed, so a store of several topologies fails without leaving a folder behind.
pub(crate) fn train_acap(cfg: &BdlstmRunConfig, opts: &BdlstmRunOptions) -> Result<(RunFolder, Outcome)> {
    if let Some(vae) = &opts.vae_run {
        return Err(no_vae(vae));
    }
    let devices = run_devices(&cfg.device, None)?;
    let objective = AcapObjective::new(cfg, &opts.run.data, None)?;
    let run = RunFolder::create(&opts.run.runs_dir, &opts.run.name, &cfg.to_toml()?, &BDLSTM_TERMS)?;
    objective.record().write(&run)?;
    let outcome = run_acap(cfg, &run, &opts.run, &objective, &devices[0], None)?;
    Ok((run, outcome))
}

/// Continues an ACAP BD-LSTM run from checkpoint `ckpt` with the reference and scaling of its `acap.json`.
pub(crate) fn resume_acap(
    cfg: &BdlstmRunConfig,
    run: &RunFolder,
    ckpt: PathBuf,
    opts: &BdlstmRunOptions,
) -> Result<Outcome> {
    if let Some(vae) = &opts.vae_run {
        return Err(no_vae(vae));
    }
    let devices = run_devices(&cfg.device, None)?;
    let record = AcapRecord::read(run.root())?;
    let objective = AcapObjective::new(cfg, &opts.run.data, Some(record))?;
    run_acap(cfg, run, &opts.run, &objective, &devices[0], Some(ckpt))
}

fn no_vae(vae: &Path) -> TrainError {
    TrainError::Setup(format!(
        "--vae {}: the ACAP variant (model.variant = \"acap\") trains on the ACAP features of the store's vertices, \
         not on VAE latents; drop --vae",
        vae.display()
    ))
}

fn run_acap(
    cfg: &BdlstmRunConfig,
    run: &RunFolder,
    opts: &RunOptions,
    objective: &AcapObjective,
    device: &Device,
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    run.log(&format!(
        "BD-LSTM (ACAP) on {} ({} train clips / {} val clips, {} vertices, reference {}, features {:.1} MiB), \
         backend {}",
        opts.data.display(),
        objective.train_len(),
        objective.valid_len(),
        objective.vertices(),
        objective.record().reference_clip,
        objective.cached_bytes() as f64 / (1024.0 * 1024.0),
        cfg.device.backend
    ))?;
    let ad = device.clone().autodiff();
    ad.seed(cfg.train.seed);
    let model = cfg.init_acap(objective.vertices(), &ad);
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: ad,
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
        init: None,
    };
    let (_, outcome) = loop_common::train(objective, model, setup)?;
    Ok(outcome)
}

/// A trained ACAP BD-LSTM run ready for completion.
pub struct LoadedAcapBdlstm {
    /// The network with the newest checkpoint's parameters (the average when the run keeps one).
    pub model: BdLstm<MeshConvCodec>,
    /// The run's resolved config.
    pub config: BdlstmRunConfig,
    /// Reference mesh and feature scaling.
    pub record: AcapRecord,
    /// The run folder (canonical path).
    pub run: PathBuf,
    /// Its newest checkpoint's step.
    pub step: u64,
}

/// Loads an ACAP BD-LSTM run onto `device`: `config.toml`, `acap.json` and the newest checkpoint.
pub fn load_acap_bdlstm_run(run_dir: &Path, device: &Device) -> Result<LoadedAcapBdlstm> {
    let (run, config) = read_bdlstm_config(run_dir)?;
    if config.model.variant != BdlstmVariant::Acap {
        return Err(run_err(
            &run,
            "is a BD-LSTM run of the latent variant: give it as `--bdlstm RUN` (method `bdlstm`)",
        ));
    }
    let record = AcapRecord::read(&run)?;
    let (ckpt, step) = runs::newest_checkpoint(&run)?;
    let model = config.init_acap(record.reference.len(), device);
    let (model, _) = crate::checkpoint::load_for_sampling(model, &ckpt)?;
    Ok(LoadedAcapBdlstm {
        model,
        config,
        record,
        run,
        step,
    })
}
