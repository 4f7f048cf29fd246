//! The RF's latent files (`rf.latent_cache = "disk"`, docs/training.md "Latents on disk"): the frozen VAE's encoding
//! of every clip of one store shard in one file, `shard-KKKKK.latents` in a folder, so that the shards of a large
//! store can be encoded by separate processes (`any4d train latents --shard K`, under any scheduler) and a run reads
//! each batch's latents from disk: its resident memory does not grow with the store.
//!
//! A file is a 48-byte header — the magic `A4DLAT01`, then little-endian u32 version, latent slots S, tokens P and
//! channels C, u64 clip count, the xxh3-64 of the shard's `clips.bin` and the VAE's fingerprint — and one record
//! per clip in shard order: z₀ `[P, C]`, μ `[S, P, C]`, log σ² `[S, P, C]`, f32 little-endian. A file whose header
//! does not match the shard and the VAE it is used with is stale: a run encodes it again. No size a file claims is
//! used before it is checked against the file's length.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use any4d_data::DataError;
use any4d_data::store::Store;
use burn::prelude::Device;

use crate::checkpoint::{EMA_FILE, MODEL_FILE};
use crate::error::{Result, TrainError};
use crate::runs::LoadedVae;

use super::latents::{ClipLatents, LatentSet, encode_latents_on_workers};

/// First bytes of a latent file.
pub const MAGIC: [u8; 8] = *b"A4DLAT01";
/// Format version in the header.
pub const VERSION: u32 = 1;
/// Bytes before the first record.
pub const HEADER_BYTES: u64 = 48;

/// The file of shard `k` in the latent folder `dir`.
pub fn shard_file(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("shard-{k:05}.latents"))
}

/// What a latent file's header records (after the magic and the version).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LatentHeader {
    /// Latent slots S per clip: T frames (frame-wise VAE) or 1 (sequence-wise).
    pub slots: u32,
    /// Tokens P.
    pub tokens: u32,
    /// Channels C.
    pub channels: u32,
    /// Clips in the shard.
    pub clips: u64,
    /// xxh3-64 of the shard's `clips.bin` ([`Store::shard_checksum`]).
    pub shard: u64,
    /// The VAE's fingerprint ([`vae_fingerprint`]).
    pub vae: u64,
}

impl LatentHeader {
    /// The header that shard `k` of `store` encoded by `vae` (fingerprint `fingerprint`) must have.
    pub fn expected(store: &Store, k: usize, vae: &LoadedVae, fingerprint: u64) -> Result<Self> {
        let slots = if vae.model.clip_frames().is_some() {
            1
        } else {
            store.frames()
        };
        let small = |what: &str, v: usize| {
            u32::try_from(v).map_err(|_| TrainError::Setup(format!("latent files: {what} {v} does not fit 32 bits")))
        };
        Ok(Self {
            slots: small("slots", slots)?,
            tokens: small("tokens", vae.tokens())?,
            channels: small("channels", vae.config.model.latent_channels())?,
            clips: store.shard_range(k).len() as u64,
            shard: store.shard_checksum(k)?,
            vae: fingerprint,
        })
    }

    /// f32 values of one clip's record: P·C·(1 + 2S); `None` on overflow.
    fn record_floats(&self) -> Option<u64> {
        let pc = u64::from(self.tokens).checked_mul(u64::from(self.channels))?;
        pc.checked_mul(1 + 2 * u64::from(self.slots))
    }

    /// Bytes of one record; `None` on overflow.
    fn record_bytes(&self) -> Option<u64> {
        self.record_floats()?.checked_mul(4)
    }

    /// Bytes of the whole file; `None` on overflow.
    fn file_bytes(&self) -> Option<u64> {
        self.record_bytes()?.checked_mul(self.clips)?.checked_add(HEADER_BYTES)
    }

    fn to_bytes(self) -> [u8; HEADER_BYTES as usize] {
        let mut b = [0u8; HEADER_BYTES as usize];
        b[..8].copy_from_slice(&MAGIC);
        for (i, v) in [VERSION, self.slots, self.tokens, self.channels]
            .into_iter()
            .enumerate()
        {
            b[8 + 4 * i..12 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        for (i, v) in [self.clips, self.shard, self.vae].into_iter().enumerate() {
            b[24 + 8 * i..32 + 8 * i].copy_from_slice(&v.to_le_bytes());
        }
        b
    }

    /// Parses a header; the reason when it is not one of this version.
    fn parse(b: &[u8; HEADER_BYTES as usize]) -> std::result::Result<Self, String> {
        if b[..8] != MAGIC {
            return Err(format!(
                "starts with {:?}, not the latent-file magic {:?}",
                &b[..8],
                MAGIC
            ));
        }
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().expect("4 bytes"));
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        let version = u32_at(8);
        if version != VERSION {
            return Err(format!("format version {version}, this build reads {VERSION}"));
        }
        Ok(Self {
            slots: u32_at(12),
            tokens: u32_at(16),
            channels: u32_at(20),
            clips: u64_at(24),
            shard: u64_at(32),
            vae: u64_at(40),
        })
    }

    /// Why `self` (a file's header) is not `expected`, in words; `None` when they agree.
    fn mismatch(&self, expected: &Self) -> Option<String> {
        if self.vae != expected.vae {
            return Some("encoded by another VAE (or another checkpoint of it)".into());
        }
        if self.shard != expected.shard {
            return Some("of another content of the shard (re-imported since it was encoded)".into());
        }
        let got = (self.slots, self.tokens, self.channels, self.clips);
        let want = (expected.slots, expected.tokens, expected.channels, expected.clips);
        (got != want).then(|| format!("(S, P, C, clips) = {got:?}, expected {want:?}"))
    }
}

/// The fingerprint of a loaded VAE: xxh3-64 of its checkpoint's parameter files (`model.bpk`, and the averaged
/// parameters when the run keeps them) and of its token count P.
pub fn vae_fingerprint(vae: &LoadedVae) -> Result<u64> {
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    for name in [MODEL_FILE, EMA_FILE] {
        let path = vae.checkpoint.join(name);
        match std::fs::read(&path) {
            Ok(bytes) => hasher.update(&bytes),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && name == EMA_FILE => {}
            Err(source) => {
                return Err(TrainError::Io {
                    op: "read",
                    path,
                    source,
                });
            }
        }
    }
    hasher.update(&(vae.tokens() as u64).to_le_bytes());
    Ok(hasher.digest())
}

/// The state of one latent file against the header it must have.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FileState {
    /// Present and of the expected header and length.
    Current,
    /// No such file.
    Missing,
    /// Present but not usable: the reason.
    Stale(String),
}

/// Checks the latent file `path` against `expected`: its header and its length (reads the header only).
pub fn check_file(path: &Path, expected: &LatentHeader) -> Result<FileState> {
    let mut file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(FileState::Missing),
        Err(source) => {
            return Err(TrainError::Io {
                op: "open",
                path: path.to_path_buf(),
                source,
            });
        }
    };
    let io = |source| TrainError::Io {
        op: "read",
        path: path.to_path_buf(),
        source,
    };
    let size = file.metadata().map_err(io)?.len();
    if size < HEADER_BYTES {
        return Ok(FileState::Stale(format!(
            "{size} bytes, shorter than the {HEADER_BYTES}-byte header"
        )));
    }
    let mut bytes = [0u8; HEADER_BYTES as usize];
    file.read_exact(&mut bytes).map_err(io)?;
    let header = match LatentHeader::parse(&bytes) {
        Ok(h) => h,
        Err(reason) => return Ok(FileState::Stale(reason)),
    };
    if let Some(reason) = header.mismatch(expected) {
        return Ok(FileState::Stale(reason));
    }
    match expected.file_bytes() {
        Some(want) if want == size => Ok(FileState::Current),
        Some(want) => Ok(FileState::Stale(format!(
            "{size} bytes, its header implies {want} (truncated or extended)"
        ))),
        None => Ok(FileState::Stale("its header's sizes overflow 64 bits".into())),
    }
}

/// How latent files are encoded: the frozen VAE, micro-batches, CPU workers and the inference device.
pub struct Encoder<'a> {
    /// The frozen VAE.
    pub vae: &'a LoadedVae,
    /// Its fingerprint ([`vae_fingerprint`]).
    pub fingerprint: u64,
    /// Clips per VAE forward.
    pub micro_batch: usize,
    /// CPU workers ([`encode_latents_on_workers`]).
    pub workers: usize,
    /// Inference device.
    pub device: &'a Device,
}

impl<'a> Encoder<'a> {
    /// An encoder of `vae` (its fingerprint computed here).
    pub fn new(vae: &'a LoadedVae, micro_batch: usize, workers: usize, device: &'a Device) -> Result<Self> {
        Ok(Self {
            vae,
            fingerprint: vae_fingerprint(vae)?,
            micro_batch: micro_batch.max(1),
            workers: workers.max(1),
            device,
        })
    }

    /// Makes shard `k`'s latent file in `dir` current: kept when it already is, (re-)encoded otherwise, written
    /// atomically so that a killed encoding leaves the old file or none. Returns the header and the state the file
    /// was found in.
    pub fn prepare_shard(&self, dir: &Path, store: &Store, k: usize) -> Result<(LatentHeader, FileState)> {
        let header = LatentHeader::expected(store, k, self.vae, self.fingerprint)?;
        let path = shard_file(dir, k);
        let state = check_file(&path, &header)?;
        if state != FileState::Current {
            std::fs::create_dir_all(dir).map_err(|source| TrainError::Io {
                op: "create folder",
                path: dir.to_path_buf(),
                source,
            })?;
            self.write_shard(&path, store, k, &header)?;
        }
        Ok((header, state))
    }

    fn write_shard(&self, path: &Path, store: &Store, k: usize, header: &LatentHeader) -> Result<()> {
        let indices: Vec<usize> = store.shard_range(k).collect();
        let chunk = self.micro_batch * self.workers * 4;
        let mut failure = None;
        let written = any4d_data::io::write_atomic_with(path, |out, tmp| {
            let io = |e| DataError::io(tmp, e);
            out.write_all(&header.to_bytes()).map_err(io)?;
            for part in indices.chunks(chunk) {
                let set = match encode_latents_on_workers(
                    &self.vae.model,
                    store,
                    part,
                    self.micro_batch,
                    self.vae.tokens(),
                    self.device,
                    self.workers,
                    None,
                ) {
                    Ok(set) => set,
                    Err(e) => {
                        failure = Some(e);
                        return Err(DataError::new(tmp, "latents", "encoding failed"));
                    }
                };
                let dims = (set.frames, set.tokens, set.channels);
                let want = (header.slots as usize, header.tokens as usize, header.channels as usize);
                if dims != want {
                    return Err(DataError::new(
                        tmp,
                        "latents",
                        format!("the VAE encodes (S, P, C) = {dims:?}, the header says {want:?}"),
                    ));
                }
                for clip in &set.clips {
                    for v in clip.z0.iter().chain(&clip.mu).chain(&clip.logvar) {
                        out.write_all(&v.to_le_bytes()).map_err(io)?;
                    }
                }
            }
            Ok(())
        });
        match (written, failure) {
            (_, Some(e)) => Err(e),
            (w, None) => Ok(w?),
        }
    }
}

/// The latent files of every shard of a store, opened for reading records on demand.
pub struct DiskLatents {
    /// Per shard: its file's path and the open file.
    files: Vec<(PathBuf, Mutex<File>)>,
    header: LatentHeader,
}

impl DiskLatents {
    /// Makes every shard's latent file in `dir` current ([`Encoder::prepare_shard`]) and opens them; `report` is told
    /// each shard and the state its file was found in.
    pub fn prepare(
        dir: &Path,
        store: &Store,
        encoder: &Encoder,
        report: &mut dyn FnMut(usize, &FileState),
    ) -> Result<Self> {
        let mut files = Vec::with_capacity(store.shard_count());
        let mut first = None;
        for k in 0..store.shard_count() {
            let (header, state) = encoder.prepare_shard(dir, store, k)?;
            report(k, &state);
            // Every shard has the same S, P, C and VAE; only clips and the shard checksum differ.
            first.get_or_insert(header);
            let path = shard_file(dir, k);
            let file = File::open(&path).map_err(|source| TrainError::Io {
                op: "open",
                path: path.clone(),
                source,
            })?;
            files.push((path, Mutex::new(file)));
        }
        let header = first.ok_or_else(|| TrainError::Setup(format!("store {} has no shard", store.dir().display())))?;
        Ok(Self { files, header })
    }

    /// The latents of clips `store_ids` of `store` (the store the files were prepared for), read from their shards'
    /// files, with their captions from the store; every value is checked to be finite.
    pub fn read(&self, store: &Store, store_ids: &[usize]) -> Result<LatentSet> {
        let h = &self.header;
        let (s, p, c) = (h.slots as usize, h.tokens as usize, h.channels as usize);
        let floats = h.record_floats().expect("checked when the file was prepared") as usize;
        let mut bytes = vec![0u8; floats * 4];
        let captions = store.captions(store_ids)?;
        let mut clips = Vec::with_capacity(store_ids.len());
        for (&id, caption) in store_ids.iter().zip(captions) {
            let k = store.shard_of(id)?;
            let local = (id - store.shard_range(k).start) as u64;
            let (path, file) = &self.files[k];
            let offset = HEADER_BYTES + local * (floats as u64 * 4);
            {
                let mut file = file
                    .lock()
                    .map_err(|_| TrainError::Loop("a latent-file lock was poisoned".into()))?;
                file.seek(SeekFrom::Start(offset))
                    .and_then(|_| file.read_exact(&mut bytes))
                    .map_err(|e| DataError::new(path, format!("clip {local} at byte {offset}"), e.to_string()))?;
            }
            let mut values: Vec<f32> = bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
                .collect();
            if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
                let field = match bad {
                    i if i < p * c => "z0",
                    i if i < p * c * (1 + s) => "mu",
                    _ => "logvar",
                };
                return Err(DataError::new(
                    path,
                    format!("clip {local} {field}"),
                    format!("holds {} (a latent file must hold finite values)", values[bad]),
                )
                .into());
            }
            // The record is z₀ | μ | log σ²: z₀ keeps the decoded buffer, μ and log σ² are split off (one copy each).
            let logvar = values.split_off(p * c * (1 + s));
            let mu = values.split_off(p * c);
            clips.push(ClipLatents {
                store_index: id,
                caption,
                z0: values,
                mu,
                logvar,
                scene: None,
            });
        }
        Ok(LatentSet {
            clips,
            frames: s,
            tokens: p,
            channels: c,
        })
    }
}

/// `any4d train latents`: makes the latent files of shard `shard` (or of every shard) of the store in `data`,
/// encoded by the newest checkpoint of the VAE run `vae_run` on `backend`, current in `dir`; `report` is told each
/// shard and the state its file was found in. Files already current are kept, so that several processes can each
/// take a shard and a killed one is simply run again.
pub fn encode_store_latents(
    vae_run: &Path,
    data: &Path,
    dir: &Path,
    shard: Option<usize>,
    micro_batch: usize,
    backend: crate::backend::Backend,
    report: &mut dyn FnMut(usize, &FileState),
) -> Result<()> {
    let device = crate::backend::device(backend, crate::backend::Precision::F32)?;
    let vae = crate::runs::load_vae_run(vae_run, &device)?;
    let store = Store::open(data)?;
    vae.check_store_any_kind(&store)?;
    let shards = match shard {
        Some(k) if k < store.shard_count() => k..k + 1,
        Some(k) => {
            return Err(TrainError::Setup(format!(
                "--shard {k}: the store {} has {} shard(s), numbered from 0",
                data.display(),
                store.shard_count()
            )));
        }
        None => 0..store.shard_count(),
    };
    let workers = backend.encoding_workers();
    let encoder = Encoder::new(&vae, micro_batch, workers, &device)?;
    for k in shards {
        let (_, state) = encoder.prepare_shard(dir, &store, k)?;
        report(k, &state);
    }
    Ok(())
}
