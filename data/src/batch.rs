//! burn integration of the dataset store: a `Dataset` of stored clips and a `Batcher` that pads vertices and
//! builds the masks of docs/method.md §1.3 / §2.4 (loader output of docs/method.md §2.1).

use std::sync::Arc;

use burn::data::dataloader::batcher::Batcher;
use burn::data::dataset::{Dataset, DatasetError};
use burn::prelude::*;

use crate::error::{DataError, Result};
use crate::preprocess::{Normalization, edges_from_faces, pad_vertices};
use crate::store::{Split, Store, StoredClip};

/// One dataset item: a stored clip (normalised vertices, FPS indices, (c, s), split).
pub type ClipItem = StoredClip;

/// Which clips of a store a [`ClipDataset`] serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Subset {
    /// Every clip.
    All,
    /// Only the clips of one split.
    Only(Split),
}

/// A burn dataset over a store; items are read from disk on demand.
#[derive(Debug, Clone)]
pub struct ClipDataset {
    store: Arc<Store>,
    indices: Vec<usize>,
}

impl ClipDataset {
    /// The clips of `subset`, in store order.
    pub fn new(store: Arc<Store>, subset: Subset) -> Self {
        let indices = match subset {
            Subset::All => (0..store.len()).collect(),
            Subset::Only(split) => store.indices(split),
        };
        Self { store, indices }
    }

    /// Open the store in `dir` and serve `subset`.
    pub fn open(dir: &std::path::Path, subset: Subset) -> Result<Self> {
        Ok(Self::new(Arc::new(Store::open(dir)?), subset))
    }

    /// The store index of item `i`.
    pub fn store_index(&self, i: usize) -> Option<usize> {
        self.indices.get(i).copied()
    }
}

impl Dataset<ClipItem> for ClipDataset {
    fn get(&self, index: usize) -> std::result::Result<ClipItem, DatasetError> {
        let i = self.indices[index];
        self.store.get(i).map_err(DatasetError::new)
    }

    fn len(&self) -> usize {
        self.indices.len()
    }
}

/// Padded vertex count of a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PadTo {
    /// The largest N_v of the batch.
    BatchMax,
    /// A fixed N (docs/method.md §2.4: N_max = 4096); a clip with more vertices is an error.
    Fixed(usize),
}

/// A batch of B clips with T frames, padded to N vertices, P FPS tokens each.
#[derive(Debug, Clone)]
pub struct ClipBatch {
    /// Normalised vertices, zero for padded rows. `[B, T, N, 3]`.
    pub vertices: Tensor<4>,
    /// True for the first N_v rows of each clip (docs/method.md §1.3). `[B, N]`.
    pub vmask: Tensor<2, Bool>,
    /// FPS indices into the vertex axis (docs/method.md §2.5). `[B, P]`.
    pub fps: Tensor<2, Int>,
    /// N_v per clip. `[B]`.
    pub n_real: Vec<usize>,
    /// Undirected, deduplicated mesh edges per clip (docs/method.md §2.1), indices `< N_v`.
    pub edges: Vec<Vec<[u32; 2]>>,
    /// Captions ("" = unconditional). `[B]`.
    pub captions: Vec<String>,
    /// Clip ids. `[B]`.
    pub ids: Vec<String>,
    /// (c, s) per clip, to undo (D3). `[B]`.
    pub normalization: Vec<Normalization>,
}

/// Stacks [`ClipItem`]s into a [`ClipBatch`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClipBatcher {
    pub pad: PadTo,
}

impl ClipBatcher {
    pub fn new(pad: PadTo) -> Self {
        Self { pad }
    }

    /// Build a batch; errors (naming the clip) if the items disagree on T or P, a clip exceeds a fixed N, or its
    /// faces index past its vertices.
    ///
    /// # Shapes
    /// - items: B clips of T frames, N_v_b vertices, P FPS indices
    /// - returns vertices `[B, T, N, 3]`, vmask `[B, N]`, fps `[B, P]`
    pub fn try_batch(&self, items: &[ClipItem], device: &Device) -> Result<ClipBatch> {
        let first = items
            .first()
            .ok_or_else(|| DataError::new("batch", "items", "a batch needs at least one clip"))?;
        let (t, p) = (first.clip.frames, first.fps.len());
        let n_max = match self.pad {
            PadTo::BatchMax => items.iter().map(|c| c.clip.n_vertices).max().unwrap_or(0),
            PadTo::Fixed(n) => n,
        };
        let b = items.len();
        let mut vertices = Vec::with_capacity(b * t * n_max * 3);
        let mut vmask = Vec::with_capacity(b * n_max);
        let mut fps = Vec::with_capacity(b * p);
        let mut edges = Vec::with_capacity(b);
        for item in items {
            let c = &item.clip;
            if c.frames != t || item.fps.len() != p {
                return Err(DataError::new(
                    &c.id,
                    "batch",
                    format!(
                        "T = {}, P = {} differ from the batch's T = {t}, P = {p}",
                        c.frames,
                        item.fps.len()
                    ),
                ));
            }
            let (v, m) = pad_vertices(&c.vertices, c.n_vertices, t, n_max).map_err(|e| e.at(&c.id))?; // §2.4
            vertices.extend(v);
            vmask.extend(m);
            fps.extend(item.fps.iter().map(|&i| i64::from(i)));
            edges.push(edges_from_faces(&c.faces, c.n_vertices).map_err(|e| e.at(&c.id))?);
        }
        Ok(ClipBatch {
            vertices: Tensor::from_data(TensorData::new(vertices, [b, t, n_max, 3]), device),
            vmask: Tensor::from_data(TensorData::new(vmask, [b, n_max]), device),
            fps: Tensor::from_data(TensorData::new(fps, [b, p]), device),
            n_real: items.iter().map(|c| c.clip.n_vertices).collect(),
            edges,
            captions: items.iter().map(|c| c.clip.caption.clone()).collect(),
            ids: items.iter().map(|c| c.clip.id.clone()).collect(),
            normalization: items.iter().map(|c| c.normalization).collect(),
        })
    }
}

impl Batcher<ClipItem, ClipBatch> for ClipBatcher {
    /// # Panics
    /// burn's `Batcher` cannot return an error: this panics with [`ClipBatcher::try_batch`]'s message. A store
    /// never triggers it (all clips share T and P) unless `PadTo::Fixed` is smaller than a clip.
    fn batch(&self, items: Vec<ClipItem>, device: &Device) -> ClipBatch {
        match self.try_batch(&items, device) {
            Ok(batch) => batch,
            Err(e) => panic!("cannot batch clips: {e}"),
        }
    }
}
