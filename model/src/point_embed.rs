//! Fourier embeddings of the mesh VAEs (docs/method.md §3.2, §3.5): the point embedding of reference positions, the
//! per-frame offset embedding of the frame-wise VAE and the whole-clip trajectory embedding of the sequence-wise
//! DyMeshVAE (AnimateAnyMesh's PointEmbed and TrajEncoding, notes/animateanymesh.md §2.2).

use burn::nn::{Linear, LinearConfig};
use burn::prelude::*;

/// Order of the sine/cosine features produced by [`fourier_features`].
#[derive(Config, Debug, Copy, PartialEq, Eq)]
pub enum FourierOrder {
    /// Index `channel · F + k`: all frequencies of channel 0 first (AAM PointEmbed's block-diagonal basis).
    ChannelMajor,
    /// Index `k · channels + channel`: all channels at frequency 0 first (AAM TrajEncoding).
    FrequencyMajor,
}

/// Sines and cosines of `x · 2^k · π` for k = 0..freqs, as `(sin, cos)`.
///
/// # Shapes
/// - `x`: `[M, C]` (any leading axes flattened into M)
/// - returns two tensors `[M, C · freqs]`, ordered as `order` says
pub fn fourier_features(x: Tensor<2>, freqs: usize, order: FourierOrder) -> (Tensor<2>, Tensor<2>) {
    let [m, c] = x.dims();
    let device = x.device();
    let bands: Vec<f32> = (0..freqs)
        .map(|k| (2f32).powi(k as i32) * std::f32::consts::PI)
        .collect();
    let bands = Tensor::<1>::from_floats(bands.as_slice(), &device);
    let proj: Tensor<2> = match order {
        FourierOrder::ChannelMajor => {
            let p: Tensor<3> = x.unsqueeze_dim::<3>(2) * bands.reshape([1, 1, freqs]);
            p.reshape([m, c * freqs])
        }
        FourierOrder::FrequencyMajor => {
            let p: Tensor<3> = x.unsqueeze_dim::<3>(1) * bands.reshape([1, freqs, 1]);
            p.reshape([m, freqs * c])
        }
    };
    (proj.clone().sin(), proj.cos())
}

/// Configuration of [`PointEmbed`].
#[derive(Config, Debug)]
pub struct PointEmbedConfig {
    /// Output width d.
    pub d_model: usize,
    /// Number of frequencies 2^k·π, k = 0..point_freqs (paper 8).
    #[config(default = 8)]
    pub point_freqs: usize,
}

/// Point embedding: xyz → [sin (3F) ‖ cos (3F) ‖ xyz (3)] → Linear(6F + 3 → d) (docs/method.md §3.2 "Point embedding").
#[derive(Module, Debug)]
pub struct PointEmbed {
    linear: Linear,
    #[module(skip)]
    freqs: usize,
}

impl PointEmbedConfig {
    /// Builds the embedding on `device`.
    pub fn init(&self, device: &Device) -> PointEmbed {
        PointEmbed {
            linear: LinearConfig::new(6 * self.point_freqs + 3, self.d_model).init(device),
            freqs: self.point_freqs,
        }
    }
}

impl PointEmbed {
    /// Embeds reference positions.
    ///
    /// # Shapes
    /// - `xyz`: `[B, N, 3]`
    /// - returns `[B, N, D]`
    pub fn forward(&self, xyz: Tensor<3>) -> Tensor<3> {
        let [b, n, _] = xyz.dims();
        let flat = xyz.reshape([b * n, 3]);
        let (sin, cos) = fourier_features(flat.clone(), self.freqs, FourierOrder::ChannelMajor);
        let features = Tensor::cat(vec![sin, cos, flat], 1);
        let width = features.dims()[1];
        self.linear.forward(features.reshape([b, n, width]))
    }
}

/// Configuration of [`OffsetEmbed`].
#[derive(Config, Debug)]
pub struct OffsetEmbedConfig {
    /// Number of raw input channels: 3 for one frame's offset, 3T (48) for a whole clip's trajectory.
    pub d_input: usize,
    /// Output width d.
    pub d_model: usize,
    /// Number of frequencies 2^j·π, j = 0..offset_freqs (paper 10).
    #[config(default = 10)]
    pub offset_freqs: usize,
}

/// Offset / trajectory embedding: r → [r (c) ‖ sin (F·c) ‖ cos (F·c)] (frequency-major) → Linear(c(2F+1) → d).
/// With c = 3 this is the frame-wise offset embedding (63 → d); with c = 48 the sequence-wise
/// trajectory embedding (1008 → d) (docs/method.md §3.2 "Offset embedding", §3.5).
#[derive(Module, Debug)]
pub struct OffsetEmbed {
    linear: Linear,
    #[module(skip)]
    freqs: usize,
}

impl OffsetEmbedConfig {
    /// Builds the embedding on `device`.
    pub fn init(&self, device: &Device) -> OffsetEmbed {
        let features = self.d_input * (2 * self.offset_freqs + 1);
        OffsetEmbed {
            linear: LinearConfig::new(features, self.d_model).init(device),
            freqs: self.offset_freqs,
        }
    }
}

impl OffsetEmbed {
    /// Embeds offsets over the last axis.
    ///
    /// # Shapes
    /// - `offsets`: `[B, G, N, c]` (G = T frames for the frame-wise VAE, G = 1 for the sequence-wise one)
    /// - returns `[B, G, N, D]`
    pub fn forward(&self, offsets: Tensor<4>) -> Tensor<4> {
        let [b, g, n, c] = offsets.dims();
        let flat = offsets.reshape([b * g * n, c]);
        let (sin, cos) = fourier_features(flat.clone(), self.freqs, FourierOrder::FrequencyMajor);
        let features = Tensor::cat(vec![flat, sin, cos], 1);
        let width = features.dims()[1];
        self.linear.forward(features.reshape([b, g, n, width]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fourier_orders_place_frequencies_as_documented() {
        let device = Device::flex();
        let x = Tensor::<2>::from_floats([[0.1f32, 0.3]], &device);
        let (sin_c, cos_c) = fourier_features(x.clone(), 2, FourierOrder::ChannelMajor);
        let (sin_f, cos_f) = fourier_features(x, 2, FourierOrder::FrequencyMajor);
        let pi = std::f32::consts::PI;
        // Channel-major: [x0·π, x0·2π, x1·π, x1·2π]; frequency-major: [x0·π, x1·π, x0·2π, x1·2π].
        let arg_c = [0.1 * pi, 0.2 * pi, 0.3 * pi, 0.6 * pi];
        let arg_f = [0.1 * pi, 0.3 * pi, 0.2 * pi, 0.6 * pi];
        let vec = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().expect("f32 data");
        let (sc, cc, sf, cf) = (vec(sin_c), vec(cos_c), vec(sin_f), vec(cos_f));
        for i in 0..4 {
            assert!((sc[i] - arg_c[i].sin()).abs() < 1e-6, "channel-major sin {i}: {sc:?}");
            assert!((cc[i] - arg_c[i].cos()).abs() < 1e-6, "channel-major cos {i}: {cc:?}");
            assert!((sf[i] - arg_f[i].sin()).abs() < 1e-6, "frequency-major sin {i}: {sf:?}");
            assert!((cf[i] - arg_f[i].cos()).abs() < 1e-6, "frequency-major cos {i}: {cf:?}");
        }
    }

    #[test]
    fn embeddings_have_paper_input_widths() {
        let device = Device::flex();
        let p = PointEmbedConfig::new(16).init(&device);
        assert_eq!(p.linear.weight.dims(), [51, 16]);
        let o = OffsetEmbedConfig::new(3, 16).init(&device);
        assert_eq!(o.linear.weight.dims(), [63, 16]);
        let t = OffsetEmbedConfig::new(48, 16).init(&device);
        assert_eq!(t.linear.weight.dims(), [1008, 16]);
        let out = o.forward(Tensor::zeros([2, 4, 5, 3], &device));
        assert_eq!(out.dims(), [2, 4, 5, 16]);
        let out = p.forward(Tensor::zeros([2, 5, 3], &device));
        assert_eq!(out.dims(), [2, 5, 16]);
    }
}
