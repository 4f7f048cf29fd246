//! Mesh convolution of the faithful BD-LSTM (Qiao et al., Eq. 2): y_i = W₁ x_i + W₂ (Σ_j x_{n_ij}) / d_i + b over the
//! one-ring of a fixed topology, and the encoder/decoder built from it on per-vertex ACAP features.

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::IndexingUpdateOp;
use burn::tensor::activation::tanh;

use super::codec::{FrameCodec, LOGVAR_MAX, LOGVAR_MIN};
use crate::attention::{EdgeList, EdgeListError};

/// The one-ring graph of one fixed topology, shared by every clip of a batch.
#[derive(Debug, Clone)]
pub struct MeshGraph {
    /// Both directions of every undirected edge (one clip).
    pub edges: EdgeList,
    /// 1 / degree per vertex, 0 for an isolated vertex (its neighbour term is zero), `[N, 1]`.
    pub inv_degree: Tensor<2>,
}

impl MeshGraph {
    /// Builds the graph of `n` vertices from undirected edges (duplicates and order do not matter).
    ///
    /// # Errors
    /// [`EdgeListError`] when an edge names a vertex ≥ `n` or is a self-loop.
    pub fn new(edges: &[[u32; 2]], n: usize, device: &Device) -> Result<Self, EdgeListError> {
        let list = EdgeList::new(&[edges.to_vec()], n, device)?;
        // The same deduplication as the edge list: every undirected edge counts once at each end.
        let mut undirected: Vec<(u32, u32)> = edges.iter().map(|&[a, b]| (a.min(b), a.max(b))).collect();
        undirected.sort_unstable();
        undirected.dedup();
        let mut degree = vec![0.0f32; n];
        for (a, b) in undirected {
            degree[a as usize] += 1.0;
            degree[b as usize] += 1.0;
        }
        let inv: Vec<f32> = degree.iter().map(|&d| if d > 0.0 { 1.0 / d } else { 0.0 }).collect();
        Ok(Self {
            edges: list,
            inv_degree: Tensor::from_data(TensorData::new(inv, [n, 1]), device),
        })
    }

    /// Number of vertices N.
    pub fn vertices(&self) -> usize {
        self.edges.vertices
    }

    /// Mean of each vertex's one-ring neighbours (zero for an isolated vertex).
    ///
    /// # Shapes
    /// - `x`: `[B, N, C]` → `[B, N, C]`
    pub fn neighbour_mean(&self, x: Tensor<3>) -> Tensor<3> {
        let [b, n, c] = x.dims();
        assert_eq!(
            n,
            self.vertices(),
            "mesh graph of {} vertices, features of {n}",
            self.vertices()
        );
        if self.edges.num_edges == 0 {
            return x.zeros_like();
        }
        let flat = x.swap_dims(0, 1).reshape([n, b * c]);
        let msg = flat.clone().select(0, self.edges.src.clone());
        let sum = flat
            .zeros_like()
            .select_assign(0, self.edges.dst.clone(), msg, IndexingUpdateOp::Add);
        (sum * self.inv_degree.clone()).reshape([n, b, c]).swap_dims(0, 1)
    }
}

/// One mesh convolution (Qiao et al., Eq. 2).
#[derive(Module, Debug)]
pub struct MeshConv {
    self_weight: Linear,
    neighbour_weight: Linear,
}

impl MeshConv {
    /// A convolution from `c_in` to `c_out` channels per vertex (W₁ with the bias b, W₂ without).
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            self_weight: LinearConfig::new(c_in, c_out).init(device),
            neighbour_weight: LinearConfig::new(c_in, c_out).with_bias(false).init(device),
        }
    }

    /// # Shapes
    /// - `x`: `[B, N, C_in]` → `[B, N, C_out]`
    pub fn forward(&self, x: Tensor<3>, graph: &MeshGraph) -> Tensor<3> {
        self.self_weight.forward(x.clone()) + self.neighbour_weight.forward(graph.neighbour_mean(x))
    }
}

/// Configuration of [`MeshConvCodec`].
#[derive(Config, Debug)]
pub struct MeshConvCodecConfig {
    /// Vertices N of the fixed topology.
    pub vertices: usize,
    /// Channels per vertex (9 ACAP channels).
    #[config(default = 9)]
    pub channels: usize,
    /// Mesh convolutions in the encoder (the decoder mirrors them).
    #[config(default = 3)]
    pub conv_layers: usize,
    /// Latent width Z (LSTM input and hidden width).
    #[config(default = 128)]
    pub latent: usize,
}

impl MeshConvCodecConfig {
    /// Builds the codec on `device`.
    pub fn init(&self, device: &Device) -> MeshConvCodec {
        let convs = |n| {
            (0..n)
                .map(|_| MeshConv::new(self.channels, self.channels, device))
                .collect()
        };
        let flat = self.vertices * self.channels;
        MeshConvCodec {
            encoder: convs(self.conv_layers),
            to_mu: LinearConfig::new(flat, self.latent).init(device),
            to_logvar: LinearConfig::new(flat, self.latent).init(device),
            from_latent: LinearConfig::new(self.latent, flat).init(device),
            decoder: convs(self.conv_layers),
            vertices: self.vertices,
            channels: self.channels,
            latent: self.latent,
        }
    }
}

/// The original's encoder/decoder: tanh mesh convolutions → flatten → Linear → μ, logσ²; decoder
/// Linear(Z → N·C) followed by mesh convolutions mirroring the encoder (tanh on all but the last), giving ΔX.
#[derive(Module, Debug)]
pub struct MeshConvCodec {
    encoder: Vec<MeshConv>,
    to_mu: Linear,
    to_logvar: Linear,
    from_latent: Linear,
    decoder: Vec<MeshConv>,
    #[module(skip)]
    vertices: usize,
    #[module(skip)]
    channels: usize,
    #[module(skip)]
    latent: usize,
}

impl FrameCodec for MeshConvCodec {
    type Context = MeshGraph;

    fn latent_width(&self) -> usize {
        self.latent
    }

    fn encode(&self, x: Tensor<3>, graph: &MeshGraph) -> (Tensor<2>, Tensor<2>) {
        let [b, n, _] = x.dims();
        assert_eq!(
            n, self.vertices,
            "mesh codec built for {} vertices, got {n}",
            self.vertices
        );
        let h = self.encoder.iter().fold(x, |h, conv| tanh(conv.forward(h, graph)));
        let flat = h.reshape([b, n * self.channels]);
        let mu = self.to_mu.forward(flat.clone());
        let logvar = self.to_logvar.forward(flat).clamp(LOGVAR_MIN, LOGVAR_MAX);
        (mu, logvar)
    }

    fn decode(&self, h: Tensor<2>, graph: &MeshGraph) -> Tensor<3> {
        let [b, _] = h.dims();
        let mut x = self.from_latent.forward(h).reshape([b, self.vertices, self.channels]);
        let last = self.decoder.len().saturating_sub(1);
        for (i, conv) in self.decoder.iter().enumerate() {
            x = conv.forward(x, graph);
            if i < last {
                x = tanh(x);
            }
        }
        x
    }
}
