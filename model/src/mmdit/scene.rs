//! Scene conditioning of the MMDiT (docs/method.md §4.12, not in the paper): the occupancy grid (S1) as context tokens
//! beside the text (S3), and the keyframes' basis-point offsets (S2) embedded into the motion tokens (S4). Each part
//! has its own key (`model.scene.global`, `model.scene.local`) so that the ablation is a `--set`.

use burn::module::Param;
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use serde::{Deserialize, Serialize};

use any4d_data::scene::features::ClipSceneFeatures;

use crate::gelu::gelu;

/// Channels per keyframe slot of (S4): the masked offset (3) and the slot's scene flag (1).
pub const LOCAL_CHANNELS: usize = 4;

/// `[model.scene]`: which scene features the network reads (both off: the paper's network, no scene parameters).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConditioning {
    /// Global tokens from the occupancy grid (S3).
    pub global: bool,
    /// Local offsets at keyframes (S4).
    pub local: bool,
    /// The grid's cells per axis (G_x, G_y, G_z), y up (S1).
    pub grid: [usize; 3],
    /// The side h of a cell, in normalised units (S1).
    pub cell: f32,
    /// The edge of a cubic patch of cells that one context token reads (S3); divides every axis of `grid`.
    pub patch: usize,
}

impl Default for SceneConditioning {
    /// Off, with SceneMI's layout scaled to a normalised clip: 16 × 8 × 16 cells of 0.25 in patches of 4³ (32 tokens).
    fn default() -> Self {
        Self {
            global: false,
            local: false,
            grid: [16, 8, 16],
            cell: 0.25,
            patch: 4,
        }
    }
}

impl SceneConditioning {
    /// Whether the network reads any scene feature.
    pub fn any(&self) -> bool {
        self.global || self.local
    }

    /// The layout of (S1) that the data side computes.
    pub fn grid_spec(&self) -> any4d_data::scene::features::GridSpec {
        any4d_data::scene::features::GridSpec {
            cells: self.grid,
            cell: self.cell,
        }
    }

    /// G_x · G_y · G_z.
    pub fn grid_cells(&self) -> usize {
        self.grid.iter().product()
    }

    /// Context tokens of (S3): one per patch (0 without the global part).
    pub fn tokens(&self) -> usize {
        if self.global {
            self.grid.iter().map(|g| g / self.patch).product()
        } else {
            0
        }
    }

    /// Cells read by one context token.
    fn patch_cells(&self) -> usize {
        self.patch.pow(3)
    }

    /// Checks the layout when a part is on; the error names the key.
    pub fn validate(&self) -> Result<(), String> {
        if !self.any() {
            return Ok(());
        }
        if let Some(g) = self.grid.iter().find(|&&g| !(1..=64).contains(&g)) {
            return Err(format!(
                "model.scene.grid has {g} cells along an axis; each must be 1..=64"
            ));
        }
        if self.grid_cells() > any4d_data::scene::features::MAX_GRID_CELLS {
            return Err(format!(
                "model.scene.grid {:?} has {} cells, more than {}",
                self.grid,
                self.grid_cells(),
                any4d_data::scene::features::MAX_GRID_CELLS
            ));
        }
        if !(self.cell.is_finite() && self.cell > 0.0) {
            return Err(format!("model.scene.cell {} must be finite and positive", self.cell));
        }
        if self.global && (self.patch == 0 || self.grid.iter().any(|g| g % self.patch != 0)) {
            return Err(format!(
                "model.scene.patch {} must divide every axis of model.scene.grid {:?}",
                self.patch, self.grid
            ));
        }
        Ok(())
    }

    /// Parameters of the scene parts at width `w` for `frames` keyframe slots (exact).
    pub fn param_count(&self, w: usize, frames: usize) -> usize {
        let global = if self.global {
            (self.patch_cells() + 1) * w + self.tokens() * w + 2 * w
        } else {
            0
        };
        let local = if self.local {
            (LOCAL_CHANNELS * frames + 1) * w + (w + 1) * w
        } else {
            0
        };
        global + local
    }

    /// The grid encoder, when the global part is on.
    pub(super) fn init_global(&self, width: usize, device: &Device) -> Option<GridEncoder> {
        self.global.then(|| GridEncoder {
            patch_proj: LinearConfig::new(self.patch_cells(), width).init(device),
            position: Initializer::Normal { mean: 0.0, std: 0.02 }.init([self.tokens(), width], device),
            norm: LayerNormConfig::new(width).init(device),
            grid: self.grid,
            patch: self.patch,
        })
    }

    /// The keyframe-offset embedding, when the local part is on; its output layer starts at zero, so a network
    /// starts as if it had no local part.
    pub(super) fn init_local(&self, width: usize, frames: usize, device: &Device) -> Option<KeyframeSceneEmbed> {
        self.local.then(|| KeyframeSceneEmbed {
            fc1: LinearConfig::new(LOCAL_CHANNELS * frames, width).init(device),
            fc2: LinearConfig::new(width, width)
                .with_initializer(Initializer::Zeros)
                .init(device),
        })
    }
}

/// What the network is told about the scene of each clip of a batch.
#[derive(Clone, Debug)]
pub struct SceneInput {
    /// Occupancy grids (S1), `[B, G]` in the cell order of (S1); zero for a clip without a scene.
    pub grid: Tensor<2>,
    /// Per token and slot `[m_f·b_{f,p} ‖ m_f·s]` (S4), `[B, P, T, 4]`; s = 1 for a clip with a scene.
    pub keyframes: Tensor<4>,
}

impl SceneInput {
    /// (S4)'s slot features from the offsets of every frame and the keyframe mask: offsets of frames that are not
    /// keyframes, and of clips without a scene (`present` = 0), are zeroed.
    ///
    /// # Shapes
    /// - grid: `[B, G]`; offsets: `[B, P, T, 3]`; mask: `[B, T]` (1 = keyframe); present: `[B]`
    pub fn new(grid: Tensor<2>, offsets: Tensor<4>, mask: Tensor<2>, present: Tensor<1>) -> Self {
        let [b, p, t, _] = offsets.dims();
        let m = (mask * present.reshape([b, 1]))
            .reshape([b, 1, t, 1])
            .expand([b, p, t, 1]);
        let keyframes = Tensor::cat(vec![offsets * m.clone(), m], 3);
        Self { grid, keyframes }
    }

    /// The input of a batch from each clip's (S1)–(S2) features (docs/method.md §4.12): a clip without a scene
    /// gets an empty grid and no offsets.
    ///
    /// # Shapes
    /// - scenes: B entries with grid `[G]` and offsets `[T, P, 3]`; mask `[B, T]`; output grid `[B, G]`, keyframes
    ///   `[B, P, T, 4]`
    pub fn from_features(
        scenes: &[Option<&ClipSceneFeatures>],
        cells: usize,
        frames: usize,
        tokens: usize,
        mask: Tensor<2>,
        device: &Device,
    ) -> SceneInput {
        let b = scenes.len();
        let mut grid = vec![0f32; b * cells];
        let mut offsets = vec![0f32; b * tokens * frames * 3];
        let mut present = vec![0f32; b];
        for (i, s) in scenes.iter().enumerate() {
            let Some(s) = s else { continue };
            assert!(
                s.grid.len() == cells && s.offsets.len() == frames * tokens * 3,
                "SceneInput::from_features: clip {i} has a grid of {} cells and {} offset values, expected {cells} and \
                 {frames} × {tokens} × 3",
                s.grid.len(),
                s.offsets.len()
            );
            present[i] = 1.0;
            grid[i * cells..(i + 1) * cells].copy_from_slice(&s.grid);
            // [T, P, 3] → [P, T, 3], the token-major layout of the latents.
            for f in 0..frames {
                for p in 0..tokens {
                    let from = (f * tokens + p) * 3;
                    let to = ((i * tokens + p) * frames + f) * 3;
                    offsets[to..to + 3].copy_from_slice(&s.offsets[from..from + 3]);
                }
            }
        }
        Self::new(
            Tensor::from_data(TensorData::new(grid, [b, cells]), device),
            Tensor::from_data(TensorData::new(offsets, [b, tokens, frames, 3]), device),
            mask,
            Tensor::from_data(TensorData::new(present, [b]), device),
        )
    }

    /// No scene for any of `b` clips: an empty grid and no offsets (what a clip without a scene gets in training).
    pub fn none(b: usize, cells: usize, tokens: usize, frames: usize, device: &Device) -> Self {
        Self {
            grid: Tensor::zeros([b, cells], device),
            keyframes: Tensor::zeros([b, tokens, frames, LOCAL_CHANNELS], device),
        }
    }

    /// The batch twice (the two branches of classifier-free guidance see the same scene).
    pub fn doubled(&self) -> Self {
        Self {
            grid: Tensor::cat(vec![self.grid.clone(), self.grid.clone()], 0),
            keyframes: Tensor::cat(vec![self.keyframes.clone(), self.keyframes.clone()], 0),
        }
    }
}

/// (S3): the occupancy grid cut into cubic patches, each projected to one context token with a learned position.
#[derive(Module, Debug)]
pub struct GridEncoder {
    patch_proj: Linear,
    position: Param<Tensor<2>>,
    norm: LayerNorm,
    grid: [usize; 3],
    patch: usize,
}

impl GridEncoder {
    /// # Shapes
    /// - grid: `[B, G_x·G_y·G_z]` in the cell order (i · G_y + j) · G_z + k
    /// - output: `[B, N_s, W]`, N_s = Π G_a / patch
    pub fn forward(&self, grid: Tensor<2>) -> Tensor<3> {
        let [b, cells] = grid.dims();
        let [gx, gy, gz] = self.grid;
        assert_eq!(
            cells,
            gx * gy * gz,
            "GridEncoder: grid has {cells} cells, model expects {gx}×{gy}×{gz}"
        );
        let q = self.patch;
        let (nx, ny, nz) = (gx / q, gy / q, gz / q);
        let patches = grid
            .reshape([b, nx, q, ny, q, nz, q])
            .permute([0, 1, 3, 5, 2, 4, 6])
            .reshape([b, nx * ny * nz, q * q * q]);
        let tokens = self.patch_proj.forward(patches) + self.position.val().unsqueeze_dim::<3>(0);
        self.norm.forward(tokens)
    }
}

/// (S4): per token, the keyframe slots' `[offset ‖ flag]` through Linear → GELU → Linear (zero-initialised).
#[derive(Module, Debug)]
pub struct KeyframeSceneEmbed {
    fc1: Linear,
    fc2: Linear,
}

impl KeyframeSceneEmbed {
    /// Keyframe slots T it reads.
    pub fn frames(&self) -> usize {
        self.fc1.weight.dims()[0] / LOCAL_CHANNELS
    }

    /// # Shapes
    /// - keyframes: `[B, P, T, 4]`; output `[B, P, W]`
    pub fn forward(&self, keyframes: Tensor<4>) -> Tensor<3> {
        let [b, p, t, c] = keyframes.dims();
        assert_eq!(
            t * c,
            self.fc1.weight.dims()[0],
            "KeyframeSceneEmbed: {t} slots × {c} channels, model expects {} frames × {LOCAL_CHANNELS}",
            self.frames()
        );
        self.fc2
            .forward(gelu(self.fc1.forward(keyframes.reshape([b, p, t * c]))))
    }
}
