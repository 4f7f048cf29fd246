//! Attention shared by the mesh VAEs (docs/method.md §3.2) and usable by the MMDiT (§4.3): multi-head scaled
//! dot-product attention with a key padding mask and several value streams pooled by one attention map, and sparse
//! neighbour attention over a mesh edge list (segment softmax; a vertex without neighbours gets a zero update).
//!
//! Mask polarity: every mask in this crate's API is "true = real / kept" (docs/method.md §1.3). burn 0.22.1's fused
//! `burn::tensor::module::attention` takes the opposite polarity — its `mask` is `[B, H, Lq, Lk]` with
//! **true = masked out** (filled with −∞ before the softmax; see `attention_fallback` in
//! burn-backend-0.22.1/src/backend/ops/modules/attention.rs and the flex kernel's "nonzero = masked out"), and
//! a fully masked row yields zeros, not NaN. [`scaled_dot_product`] inverts and expands our mask for it.

use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::prelude::*;
use burn::tensor::IndexingUpdateOp;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;

/// Scaled dot-product attention softmax(q kᵀ / √Dh) v through burn's fused op, with an optional key padding mask.
///
/// # Shapes
/// - `q`: `[B, H, Lq, Dh]`, `k`: `[B, H, Lk, Dh]`, `v`: `[B, H, Lk, Dv]` (Dv may differ from Dh)
/// - `key_mask`: `[B, Lk]`, true = real key; a query row whose keys are all masked gets zeros
/// - returns `[B, H, Lq, Dv]`
pub fn scaled_dot_product(q: Tensor<4>, k: Tensor<4>, v: Tensor<4>, key_mask: Option<Tensor<2, Bool>>) -> Tensor<4> {
    let [b, h, lq, _] = q.dims();
    let lk = k.dims()[2];
    // burn's mask: true = masked out, full [B, H, Lq, Lk] shape (the autodiff fallback does not broadcast).
    let mask = key_mask.map(|m| m.bool_not().reshape([b, 1, 1, lk]).expand([b, h, lq, lk]));
    attention(
        q,
        k,
        v,
        mask,
        None,
        AttentionModuleOptions {
            scale: None,
            softcap: None,
            is_causal: false,
        },
    )
}

/// How an output projection starts.
#[derive(Config, Debug, Copy, PartialEq, Eq)]
pub enum OutInit {
    /// burn's default Linear initialisation.
    Default,
    /// All weights and the bias zero, so the layer starts as "no update" (AAM neighbour / query attention).
    Zeros,
}

fn out_linear(d_in: usize, d_out: usize, init: OutInit, device: &Device) -> Linear {
    let cfg = LinearConfig::new(d_in, d_out);
    match init {
        OutInit::Default => cfg.init(device),
        OutInit::Zeros => cfg.with_initializer(Initializer::Zeros).init(device),
    }
}

/// Configuration of [`SharedMapAttention`].
#[derive(Config, Debug)]
pub struct SharedMapAttentionConfig {
    /// Query input width.
    pub d_query: usize,
    /// Key input width.
    pub d_key: usize,
    /// Input width of each value stream.
    pub d_values: Vec<usize>,
    /// Output width of each value stream (same length as `d_values`).
    pub d_outputs: Vec<usize>,
    /// Number of heads H.
    pub heads: usize,
    /// Width of one head Dh (inner width H·Dh).
    pub head_dim: usize,
    /// Initialisation of the output projections.
    #[config(default = "OutInit::Default")]
    pub out_init: OutInit,
}

/// Multi-head attention whose one attention map (from queries and keys) pools several value streams, each
/// with its own bias-free value projection and its own output projection; a stream may carry G groups (e.g.
/// T frames) that all share the map. With one stream of one group this is ordinary multi-head attention.
/// Query, key and value projections are bias-free (AAM).
#[derive(Module, Debug)]
pub struct SharedMapAttention {
    to_q: Linear,
    to_k: Linear,
    to_v: Vec<Linear>,
    to_out: Vec<Linear>,
    #[module(skip)]
    heads: usize,
    #[module(skip)]
    head_dim: usize,
}

impl SharedMapAttentionConfig {
    /// Builds the layer on `device`.
    ///
    /// # Panics
    /// If `d_values` and `d_outputs` differ in length (a programming error in a model config).
    pub fn init(&self, device: &Device) -> SharedMapAttention {
        assert_eq!(
            self.d_values.len(),
            self.d_outputs.len(),
            "one output width per value stream"
        );
        let inner = self.heads * self.head_dim;
        let no_bias = |d_in: usize| LinearConfig::new(d_in, inner).with_bias(false).init(device);
        SharedMapAttention {
            to_q: no_bias(self.d_query),
            to_k: no_bias(self.d_key),
            to_v: self.d_values.iter().map(|&d| no_bias(d)).collect(),
            to_out: self
                .d_outputs
                .iter()
                .map(|&d| out_linear(inner, d, self.out_init, device))
                .collect(),
            heads: self.heads,
            head_dim: self.head_dim,
        }
    }
}

impl SharedMapAttention {
    fn split_heads(&self, x: Tensor<3>) -> Tensor<4> {
        let [b, l, _] = x.dims();
        x.reshape([b, l, self.heads, self.head_dim]).swap_dims(1, 2)
    }

    /// Attends from `query` to `key` and pools every value stream with the same attention map.
    ///
    /// # Shapes
    /// - `query`: `[B, Lq, Dq]`, `key`: `[B, Lk, Dk]`
    /// - `values[i]`: `[B, G_i, Lk, Dv_i]` (G_i groups share the map, e.g. G = T frames)
    /// - `key_mask`: `[B, Lk]`, true = real key
    /// - returns one `[B, G_i, Lq, Dout_i]` per stream
    pub fn forward(
        &self,
        query: Tensor<3>,
        key: Tensor<3>,
        values: Vec<Tensor<4>>,
        key_mask: Option<Tensor<2, Bool>>,
    ) -> Vec<Tensor<4>> {
        assert_eq!(values.len(), self.to_v.len(), "one value tensor per value stream");
        let (h, dh) = (self.heads, self.head_dim);
        let q = self.split_heads(self.to_q.forward(query));
        let k = self.split_heads(self.to_k.forward(key));
        let [b, _, lq, _] = q.dims();
        let mut groups = Vec::with_capacity(values.len());
        // Value streams and their groups are concatenated along the head channel axis: [B, H, Lk, ΣG·Dh].
        let v_cat: Vec<Tensor<4>> = values
            .into_iter()
            .zip(&self.to_v)
            .map(|(v, proj)| {
                let [_, g, lk, _] = v.dims();
                groups.push(g);
                let v: Tensor<5> = proj.forward(v).reshape([b, g, lk, h, dh]);
                v.permute([0, 3, 2, 1, 4]).reshape([b, h, lk, g * dh])
            })
            .collect();
        let pooled = scaled_dot_product(q, k, Tensor::cat(v_cat, 3), key_mask);
        let mut start = 0;
        groups
            .into_iter()
            .zip(&self.to_out)
            .map(|(g, proj)| {
                let part: Tensor<5> = pooled.clone().narrow(3, start, g * dh).reshape([b, h, lq, g, dh]);
                start += g * dh;
                proj.forward(part.permute([0, 3, 2, 1, 4]).reshape([b, g, lq, h * dh]))
            })
            .collect()
    }

    /// One value stream pooled by the attention map and then fed through a further linear layer `post`:
    /// `post(Out(Attn(q, k, V(v))))`, computed as Σ_h A_h · v · (W_v,h W_o,h W_post) + (b_o W_post + b_post).
    /// Attention is linear in its values, so this is the same function as [`Self::forward`] followed by
    /// `post`; multiplying the three projections first makes the pooling `Dpost` wide per head instead of
    /// Dh (query decoding: 3 values per frame instead of 2d). Needs one value stream.
    ///
    /// # Shapes
    /// - `query`: `[B, Lq, Dq]`, `key`: `[B, Lk, Dk]`, `value`: `[B, G, Lk, Dv]`, `key_mask`: `[B, Lk]`
    /// - `post`: a `Dout → Dpost` layer
    /// - returns `[B, G, Lq, Dpost]`
    ///
    /// # Panics
    /// If the layer was built with more than one value stream (a programming error).
    pub fn forward_then(
        &self,
        query: Tensor<3>,
        key: Tensor<3>,
        value: Tensor<4>,
        key_mask: Option<Tensor<2, Bool>>,
        post: &Linear,
    ) -> Tensor<4> {
        assert_eq!(self.to_v.len(), 1, "forward_then needs exactly one value stream");
        let (h, dh) = (self.heads, self.head_dim);
        let q = self.split_heads(self.to_q.forward(query));
        let k = self.split_heads(self.to_k.forward(key));
        let [b, g, lk, dv] = value.dims();
        let lq = q.dims()[2];
        let (to_v, to_out) = (&self.to_v[0], &self.to_out[0]);
        let w_post = post.weight.val();
        let [d_out, d_post] = w_post.dims();
        // W_v,h W_o,h W_post for every head: [Dv, H·Dh] → [H, Dv, Dh] · [H, Dh, Dout] → [H·Dv, Dout] · W_post.
        let w_v: Tensor<3> = to_v.weight.val().reshape([dv, h, dh]).swap_dims(0, 1);
        let w_o: Tensor<3> = to_out.weight.val().reshape([h, dh, d_out]);
        let fused: Tensor<2> = w_v.matmul(w_o).reshape([h * dv, d_out]).matmul(w_post);
        let fused: Tensor<2> = fused.reshape([h, dv, d_post]).swap_dims(0, 1).reshape([dv, h * d_post]);
        // Projected values, heads first and groups along the channel axis: [B, H, Lk, G·Dpost].
        let v: Tensor<5> = value
            .reshape([b * g * lk, dv])
            .matmul(fused)
            .reshape([b, g, lk, h, d_post]);
        let v = v.permute([0, 3, 2, 1, 4]).reshape([b, h, lk, g * d_post]);
        let pooled: Tensor<3> = scaled_dot_product(q, k, v, key_mask)
            .sum_dim(1)
            .reshape([b, lq, g * d_post]);
        let mut out: Tensor<4> = pooled.reshape([b, lq, g, d_post]).swap_dims(1, 2);
        if let Some(b_o) = &to_out.bias {
            let shifted: Tensor<2> = b_o.val().reshape([1, d_out]).matmul(post.weight.val());
            out = out + shifted.reshape([1, 1, 1, d_post]);
        }
        if let Some(b_post) = &post.bias {
            out = out + b_post.val().reshape([1, 1, 1, d_post]);
        }
        out
    }

    /// Ordinary multi-head attention with one value stream.
    ///
    /// # Shapes
    /// - `query`: `[B, Lq, Dq]`, `key`: `[B, Lk, Dk]`, `value`: `[B, Lk, Dv]`, `key_mask`: `[B, Lk]` (true = real)
    /// - returns `[B, Lq, Dout]`
    pub fn forward_single(
        &self,
        query: Tensor<3>,
        key: Tensor<3>,
        value: Tensor<3>,
        key_mask: Option<Tensor<2, Bool>>,
    ) -> Tensor<3> {
        let out = self.forward(query, key, vec![value.unsqueeze_dim(1)], key_mask);
        out.into_iter().next().expect("one stream in, one out").squeeze_dim(1)
    }
}

/// Error building an [`EdgeList`].
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum EdgeListError {
    /// An edge names a vertex outside the padded vertex axis.
    #[error("edge list of clip {clip}: edge ({a}, {b}) names a vertex ≥ the padded vertex count {n}")]
    VertexOutOfRange { clip: usize, a: u32, b: u32, n: usize },
    /// An edge joins a vertex to itself (mesh edges never do).
    #[error("edge list of clip {clip}: self-loop at vertex {vertex}")]
    SelfLoop { clip: usize, vertex: u32 },
}

/// Batched sparse mesh edges for [`NeighbourAttention`], flattened over the batch (vertex v of clip b is row
/// b·N + v), each undirected edge stored in both directions, deduplicated.
#[derive(Debug, Clone)]
pub struct EdgeList {
    /// Source (key) vertex of each directed edge, `[E]`.
    pub src: Tensor<1, Int>,
    /// Destination (query) vertex of each directed edge, `[E]`.
    pub dst: Tensor<1, Int>,
    /// Whether each flattened vertex has at least one neighbour, `[B·N]`.
    pub has_neighbour: Tensor<1, Bool>,
    /// Number of directed edges E.
    pub num_edges: usize,
    /// Batch size B.
    pub batch: usize,
    /// Padded vertex count N.
    pub vertices: usize,
}

impl EdgeList {
    /// Builds the batched edges from one undirected edge list per clip over a padded vertex axis of `n`.
    ///
    /// # Errors
    /// [`EdgeListError`] when an edge names a vertex ≥ `n` or is a self-loop.
    pub fn new(clips: &[Vec<[u32; 2]>], n: usize, device: &Device) -> Result<Self, EdgeListError> {
        let mut src = Vec::new();
        let mut dst = Vec::new();
        let mut has = vec![false; clips.len() * n];
        for (clip, edges) in clips.iter().enumerate() {
            let mut undirected: Vec<(u32, u32)> = Vec::with_capacity(edges.len());
            for &[a, b] in edges {
                if a as usize >= n || b as usize >= n {
                    return Err(EdgeListError::VertexOutOfRange { clip, a, b, n });
                }
                if a == b {
                    return Err(EdgeListError::SelfLoop { clip, vertex: a });
                }
                undirected.push((a.min(b), a.max(b)));
            }
            undirected.sort_unstable();
            undirected.dedup();
            let offset = (clip * n) as i64;
            for (a, b) in undirected {
                let (a, b) = (offset + a as i64, offset + b as i64);
                src.extend([a, b]);
                dst.extend([b, a]);
                has[a as usize] = true;
                has[b as usize] = true;
            }
        }
        let num_edges = src.len();
        Ok(Self {
            src: Tensor::from_data(TensorData::new(src, [num_edges]), device),
            dst: Tensor::from_data(TensorData::new(dst, [num_edges]), device),
            has_neighbour: Tensor::from_data(TensorData::new(has, [clips.len() * n]), device),
            num_edges,
            batch: clips.len(),
            vertices: n,
        })
    }
}

/// Configuration of [`NeighbourAttention`].
#[derive(Config, Debug)]
pub struct NeighbourAttentionConfig {
    /// Feature width d.
    pub d_model: usize,
    /// Number of heads (AAM: 1).
    #[config(default = 1)]
    pub heads: usize,
    /// Width of one head (AAM: 2d).
    pub head_dim: usize,
}

/// Topology-aware neighbour attention (docs/method.md §3.2 "Neighbour attention"): x + Out(Attn(LN_q x, LN_k x, LN_v
/// x)) where each vertex attends only to its 1-ring neighbours. Keys are gathered through the edge list and the
/// softmax runs over each vertex's incident edges (segment softmax), so memory is O(E), never O(N²). The
/// output projection is zero-initialised (the layer starts as the identity) and a vertex without neighbours
/// gets a zero update.
#[derive(Module, Debug)]
pub struct NeighbourAttention {
    norm_q: LayerNorm,
    norm_k: LayerNorm,
    norm_v: LayerNorm,
    to_q: Linear,
    to_k: Linear,
    to_v: Linear,
    to_out: Linear,
    #[module(skip)]
    heads: usize,
    #[module(skip)]
    head_dim: usize,
}

impl NeighbourAttentionConfig {
    /// Builds the layer on `device`.
    pub fn init(&self, device: &Device) -> NeighbourAttention {
        let inner = self.heads * self.head_dim;
        let no_bias = || LinearConfig::new(self.d_model, inner).with_bias(false).init(device);
        NeighbourAttention {
            norm_q: LayerNormConfig::new(self.d_model).init(device),
            norm_k: LayerNormConfig::new(self.d_model).init(device),
            norm_v: LayerNormConfig::new(self.d_model).init(device),
            to_q: no_bias(),
            to_k: no_bias(),
            to_v: no_bias(),
            to_out: out_linear(inner, self.d_model, OutInit::Zeros, device),
            heads: self.heads,
            head_dim: self.head_dim,
        }
    }
}

impl NeighbourAttention {
    /// Residual neighbour attention over the mesh edges.
    ///
    /// # Shapes
    /// - `x`: `[B, N, D]`; `edges` built for the same B and N
    /// - returns `[B, N, D]`
    pub fn forward(&self, x: Tensor<3>, edges: &EdgeList) -> Tensor<3> {
        let [b, n, d] = x.dims();
        assert_eq!(
            (edges.batch, edges.vertices),
            (b, n),
            "edge list built for another batch or vertex count"
        );
        if edges.num_edges == 0 {
            return x;
        }
        let (h, dh) = (self.heads, self.head_dim);
        let flat = x.clone().reshape([b * n, d]);
        let q = self.to_q.forward(self.norm_q.forward(flat.clone()));
        let k = self.to_k.forward(self.norm_k.forward(flat.clone()));
        let v = self.to_v.forward(self.norm_v.forward(flat));
        let agg = segment_attention(
            q.reshape([b * n, h, dh]),
            k.reshape([b * n, h, dh]),
            v.reshape([b * n, h, dh]),
            edges,
        );
        let update = self.to_out.forward(agg.reshape([b * n, h * dh]));
        // Rows without neighbours: zero update, not the output bias.
        let lonely = edges
            .has_neighbour
            .clone()
            .bool_not()
            .reshape([b * n, 1])
            .expand([b * n, d]);
        x + update.mask_fill(lonely, 0.0).reshape([b, n, d])
    }
}

/// Sparse attention along directed edges: vertex `dst[e]` attends to `src[e]`, softmax over each
/// destination's incident edges (segment softmax, shifted by the per-segment maximum for stability). A vertex
/// without incident edges receives zeros.
///
/// # Shapes
/// - `q`, `k`: `[V, H, Dh]`, `v`: `[V, H, Dv]` where V = B·N flattened vertices
/// - returns `[V, H, Dv]`
pub fn segment_attention(q: Tensor<3>, k: Tensor<3>, v: Tensor<3>, edges: &EdgeList) -> Tensor<3> {
    let [nv, h, dh] = q.dims();
    let dv = v.dims()[2];
    let device = q.device();
    let e = edges.num_edges;
    let q_e = q.select(0, edges.dst.clone());
    let k_e = k.select(0, edges.src.clone());
    let scores: Tensor<2> = (q_e * k_e)
        .sum_dim(2)
        .reshape([e, h])
        .mul_scalar(1.0 / (dh as f64).sqrt());
    // The shift is a constant for the gradient (softmax is shift-invariant), so it is computed detached.
    let seg_max = Tensor::<2>::full([nv, h], -1e30, &device).select_assign(
        0,
        edges.dst.clone(),
        scores.clone().detach(),
        IndexingUpdateOp::Max,
    );
    let num = (scores - seg_max.select(0, edges.dst.clone())).exp();
    let den =
        Tensor::<2>::zeros([nv, h], &device).select_assign(0, edges.dst.clone(), num.clone(), IndexingUpdateOp::Add);
    let alpha = num / den.select(0, edges.dst.clone());
    let msg = v.select(0, edges.src.clone()) * alpha.reshape([e, h, 1]);
    Tensor::<3>::zeros([nv, h, dv], &device).select_assign(0, edges.dst.clone(), msg, IndexingUpdateOp::Add)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    fn values(t: Tensor<3>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().expect("f32 data")
    }

    #[test]
    fn segment_attention_matches_dense_softmax_and_zeroes_isolated_vertices() {
        let device = Device::flex();
        // Path 0-1-2, vertex 3 isolated.
        let edges = EdgeList::new(&[vec![[0, 1], [2, 1], [1, 0]]], 4, &device).expect("valid edges");
        assert_eq!(edges.num_edges, 4, "duplicate (1,0) removed, both directions kept");
        let q = Tensor::<3>::from_floats([[[1.0f32, 0.0]], [[0.5, 1.0]], [[0.0, 2.0]], [[3.0, 3.0]]], &device);
        let k = Tensor::<3>::from_floats([[[0.2f32, 0.1]], [[1.0, -1.0]], [[0.3, 0.7]], [[9.0, 9.0]]], &device);
        let v = Tensor::<3>::from_floats([[[1.0f32]], [[2.0]], [[4.0]], [[8.0]]], &device);
        let out = values(segment_attention(q, k, v, &edges));
        let s = 1.0 / 2f32.sqrt();
        // Vertex 1 attends to 0 and 2: scores q1·k0, q1·k2.
        let (a, b) = ((0.5 * 0.2 + 0.1) * s, (0.5 * 0.3 + 0.7) * s);
        let want1 = (a.exp() * 1.0 + b.exp() * 4.0) / (a.exp() + b.exp());
        assert!(
            (out[0] - 2.0).abs() < 1e-6,
            "vertex 0 has the single neighbour 1: {out:?}"
        );
        assert!((out[1] - want1).abs() < 1e-5, "vertex 1: {out:?} vs {want1}");
        assert!(
            (out[2] - 2.0).abs() < 1e-6,
            "vertex 2 has the single neighbour 1: {out:?}"
        );
        assert_eq!(out[3], 0.0, "isolated vertex gets zeros");
    }

    #[test]
    fn edge_list_rejects_bad_edges() {
        let device = Device::flex();
        assert_eq!(
            EdgeList::new(&[vec![[0, 4]]], 4, &device).err(),
            Some(EdgeListError::VertexOutOfRange {
                clip: 0,
                a: 0,
                b: 4,
                n: 4
            })
        );
        assert_eq!(
            EdgeList::new(&[vec![], vec![[2, 2]]], 4, &device).err(),
            Some(EdgeListError::SelfLoop { clip: 1, vertex: 2 })
        );
    }

    #[test]
    fn masked_keys_get_no_weight() {
        let device = Device::flex();
        device.seed(3);
        let att = SharedMapAttentionConfig::new(4, 4, vec![4, 4], vec![4, 4], 2, 2).init(&device);
        let q = Tensor::<3>::random([1, 3, 4], Distribution::Default, &device);
        let kv = Tensor::<3>::random([1, 5, 4], Distribution::Default, &device);
        let mask = Tensor::<2, Bool>::from_data([[true, true, true, false, false]], &device);
        let garbage = kv.clone().slice([0..1, 3..5, 0..4]).mul_scalar(0.0).add_scalar(1e3);
        let kv2 = kv.clone().slice_assign([0..1, 3..5, 0..4], garbage);
        let run = |kv: Tensor<3>| {
            let values = vec![kv.clone().unsqueeze_dim(1), kv.clone().unsqueeze_dim(1)];
            let out = att.forward(q.clone(), kv, values, Some(mask.clone()));
            out.into_iter().map(|o| o.squeeze_dim::<3>(1)).collect::<Vec<_>>()
        };
        for (x, y) in run(kv).into_iter().zip(run(kv2)) {
            for (u, w) in values(x).iter().zip(&values(y)) {
                assert!((u - w).abs() < 1e-5, "masked keys changed the output: {u} vs {w}");
            }
        }
    }

    #[test]
    fn forward_then_equals_forward_followed_by_the_layer() {
        // Folding V·Out·post into one matrix must not change the function: 3 heads, 4 groups, a masked key
        // and a fully masked query batch row (whose output is then the biases alone).
        let device = Device::flex();
        device.seed(11);
        let att = SharedMapAttentionConfig::new(5, 4, vec![6], vec![7], 3, 2).init(&device);
        let post = LinearConfig::new(7, 3).init(&device);
        let query = Tensor::<3>::random([2, 3, 5], Distribution::Default, &device);
        let key = Tensor::<3>::random([2, 4, 4], Distribution::Default, &device);
        let value = Tensor::<4>::random([2, 4, 4, 6], Distribution::Default, &device);
        let mask = Tensor::<2, Bool>::from_data([[true, false, true, true], [false, false, false, false]], &device);
        let want = post.forward(
            att.forward(query.clone(), key.clone(), vec![value.clone()], Some(mask.clone()))
                .into_iter()
                .next()
                .expect("one stream"),
        );
        let got = att.forward_then(query, key, value, Some(mask), &post);
        assert_eq!(got.dims(), [2, 4, 3, 3]);
        let (got, want) = (values(got.reshape([2, 12, 3])), values(want.reshape([2, 12, 3])));
        for (u, w) in got.iter().zip(&want) {
            assert!((u - w).abs() < 1e-5, "folded {u} vs unfolded {w}");
        }
    }

    #[test]
    fn streams_and_groups_match_per_head_reference() {
        // Two value streams (1 group and 3 groups) pooled by one map must equal a per-head softmax(q kᵀ/√Dh) v
        // computed separately for every stream and group.
        let device = Device::flex();
        device.seed(9);
        let (h, dh) = (2, 3);
        let att = SharedMapAttentionConfig::new(5, 4, vec![4, 6], vec![7, 2], h, dh).init(&device);
        let query = Tensor::<3>::random([2, 3, 5], Distribution::Default, &device);
        let key = Tensor::<3>::random([2, 4, 4], Distribution::Default, &device);
        let v0 = Tensor::<4>::random([2, 1, 4, 4], Distribution::Default, &device);
        let v1 = Tensor::<4>::random([2, 3, 4, 6], Distribution::Default, &device);
        let out = att.forward(query.clone(), key.clone(), vec![v0.clone(), v1.clone()], None);
        assert_eq!(out[0].dims(), [2, 1, 3, 7]);
        assert_eq!(out[1].dims(), [2, 3, 3, 2]);
        let q = att.to_q.forward(query).reshape([2, 3, h, dh]).swap_dims(1, 2);
        let k = att.to_k.forward(key).reshape([2, 4, h, dh]).swap_dims(1, 2);
        let map = burn::tensor::activation::softmax(q.matmul(k.swap_dims(2, 3)).div_scalar((dh as f64).sqrt()), 3);
        let reference = |v: Tensor<4>, stream: usize, g: usize| {
            let v: Tensor<3> = v.narrow(1, g, 1).squeeze_dim(1);
            let v = att.to_v[stream].forward(v).reshape([2, 4, h, dh]).swap_dims(1, 2);
            let pooled = map.clone().matmul(v).swap_dims(1, 2).reshape([2, 3, h * dh]);
            att.to_out[stream].forward(pooled)
        };
        let mut checks = vec![(out[0].clone().narrow(1, 0, 1).squeeze_dim::<3>(1), reference(v0, 0, 0))];
        for g in 0..3 {
            checks.push((
                out[1].clone().narrow(1, g, 1).squeeze_dim::<3>(1),
                reference(v1.clone(), 1, g),
            ));
        }
        for (i, (got, want)) in checks.into_iter().enumerate() {
            for (u, w) in values(got).iter().zip(&values(want)) {
                assert!((u - w).abs() < 1e-5, "stream/group {i}: {u} vs {w}");
            }
        }
    }
}
