//! What a training step costs in floating-point operations, counted from the layer shapes, and
//! this machine's FP32 matrix-multiply peak on the threads a step uses: their ratio is how
//! close the engine comes to what the cores can do.
//!
//! Counted: every convolution, Linear layer and attention product (2 FLOPs per multiply-add).
//! A training step is the forward pass and the backward, which computes for each of them the
//! weight gradient and the input gradient, each as costly as the forward product (the first
//! convolution of each encoder has no input gradient: its input is the image). Element-wise
//! work (norms, activations, softmax, the optimizer) is left out: it is memory-bound, not what
//! a matrix-multiply peak measures.

use std::time::Instant;

use crate::config::{Architecture, ModelConfig};
use crate::model::cpu::{gemm, on_pool};

/// FLOPs of one training step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StepFlops {
    /// The image encoders, forward and backward.
    pub encoders: f64,
    /// The denoiser (and its condition embeddings), forward and backward.
    pub denoiser: f64,
}

impl StepFlops {
    /// Everything.
    pub fn total(&self) -> f64 {
        self.encoders + self.denoiser
    }
}

/// (FLOPs, output height, output width) of a convolution over `h × w`.
fn conv(
    h: usize,
    w: usize,
    cin: usize,
    cout: usize,
    k: usize,
    stride: usize,
) -> (f64, usize, usize) {
    let pad = k / 2;
    let (ho, wo) = (
        (h + 2 * pad - k) / stride + 1,
        (w + 2 * pad - k) / stride + 1,
    );
    (2.0 * (cin * cout * k * k * ho * wo) as f64, ho, wo)
}

/// Forward FLOPs of one image through one encoder, and those of its first convolution.
fn encoder_forward(cfg: &ModelConfig) -> (f64, f64) {
    let (cw, ch) = cfg.crop_size();
    let w0 = cfg.resnet_width;
    let (first, mut h, mut w) = conv(ch, cw, 3, w0, 7, 2);
    // Max-pool 3×3 / 2, padding 1.
    (h, w) = ((h + 2 - 3) / 2 + 1, (w + 2 - 3) / 2 + 1);
    let mut total = first;
    let mut c = w0;
    for (stage, mult) in [1usize, 2, 4, 8].into_iter().enumerate() {
        let out = w0 * mult;
        for block in 0..2 {
            let stride = if stage > 0 && block == 0 { 2 } else { 1 };
            let (f1, h1, w1) = conv(h, w, c, out, 3, stride);
            let (f2, _, _) = conv(h1, w1, out, out, 3, 1);
            total += f1 + f2;
            if stride != 1 || c != out {
                total += conv(h, w, c, out, 1, stride).0;
            }
            (h, w, c) = (h1, w1, out);
        }
    }
    // SpatialSoftmax's 1×1 keypoint convolution, then Linear(2K → F).
    total += 2.0 * (c * cfg.keypoints * h * w) as f64;
    total += 2.0 * (2 * cfg.keypoints * cfg.feature_dim) as f64;
    (total, first)
}

/// Forward FLOPs of the denoiser for `n` observations with `k` noise draws each.
fn denoiser_forward(cfg: &ModelConfig, n: usize, k: usize) -> f64 {
    let (d, t, a) = (
        cfg.hidden as f64,
        cfg.action_chunk as f64,
        cfg.action_dim as f64,
    );
    let (m, n) = ((n * k) as f64, n as f64);
    let layers = cfg.depth as f64;
    match cfg.arch {
        Architecture::ScaleDp => {
            let per_token = 2.0 * t * (d * 3.0 * d + d * d + 2.0 * d * 4.0 * d);
            let attention = 2.0 * 2.0 * t * t * d;
            let modulation = 2.0 * d * 6.0 * d;
            let embed = 2.0 * t * a * d + 2.0 * (256.0 * d + d * d) + 2.0 * d * 2.0 * d;
            let head = 2.0 * t * d * a;
            m * (layers * (per_token + attention + modulation) + embed + head)
                + n * 2.0 * cfg.cond_dim() as f64 * d
        }
        Architecture::DpT => {
            let tc = (1 + cfg.obs_horizon) as f64;
            let self_attn = 2.0 * t * d * 3.0 * d + 2.0 * 2.0 * t * t * d + 2.0 * t * d * d;
            let cross =
                2.0 * t * d * d + 2.0 * tc * d * 2.0 * d + 2.0 * 2.0 * t * tc * d + 2.0 * t * d * d;
            let ffn = 2.0 * 2.0 * t * d * 4.0 * d;
            let memory = 2.0 * tc * 2.0 * d * 4.0 * d;
            let embed = 2.0 * t * a * d + 2.0 * t * d * a;
            m * (layers * (self_attn + cross + ffn) + memory + embed)
                + n * 2.0 * cfg.cond_dim() as f64 * d
        }
    }
}

/// The FLOPs of one training step of `batch` samples with `noise_samples` draws each.
pub fn step_flops(cfg: &ModelConfig, batch: usize, noise_samples: usize) -> StepFlops {
    let images = (batch * cfg.obs_horizon * cfg.cameras.len()) as f64;
    let (enc, first) = encoder_forward(cfg);
    StepFlops {
        encoders: images * (3.0 * enc - first),
        denoiser: 3.0 * denoiser_forward(cfg, batch, noise_samples.max(1)),
    }
}

/// This machine's FP32 matrix-multiply throughput (GFLOP/s) on rayon's threads: the best of
/// `runs` products of two `size × size` matrices by the GEMM the engine multiplies with.
pub fn matmul_peak_gflops(size: usize, runs: usize) -> f64 {
    crate::model::cpu::init_threads();
    let a: Vec<f32> = (0..size * size).map(|i| (i % 7) as f32 * 0.1).collect();
    let b: Vec<f32> = (0..size * size).map(|i| (i % 5) as f32 * 0.1).collect();
    let mut c = vec![0f32; size * size];
    let mut best = f64::INFINITY;
    for _ in 0..runs.max(1) + 1 {
        let t0 = Instant::now();
        on_pool(|| gemm(size, size, size, &a, false, &b, false, &mut c, false));
        best = best.min(t0.elapsed().as_secs_f64());
    }
    2.0 * (size as f64).powi(3) / best / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ModelSize;

    /// The counts against hand sums: ResNet-18's well-known 1.8 GFLOP (multiply-adds × 2 ≈
    /// 3.6 GFLOP) at 224×224, and a denoiser block's matrix products.
    #[test]
    fn counts_match_known_figures() {
        let cams = vec!["observation.images.front".to_string()];
        let mut cfg = ModelConfig::new(ModelSize::Ti, cams, (224, 224), 7, 7);
        cfg.crop = 1.0;
        let (enc, first) = encoder_forward(&cfg);
        // torchvision's ResNet-18 trunk (without avgpool/fc): 1.814 G multiply-adds.
        assert!((enc / 2.0 / 1e9 - 1.814).abs() < 0.02, "{}", enc / 2e9);
        assert!(
            (first / 2.0 / 1e6 - 118.0).abs() < 1.0,
            "conv1 {}",
            first / 2e6
        );
        // One ScaleDP-Ti sample: 8 blocks of 12 d² per token over 16 tokens dominate.
        let d = 256.0;
        let per_sample = denoiser_forward(&cfg, 1, 1);
        let blocks = 8.0 * (2.0 * 16.0 * 12.0 * d * d);
        assert!(
            per_sample > blocks && per_sample < 1.2 * blocks,
            "{per_sample}"
        );
        let s = step_flops(&cfg, 4, 2);
        assert!((s.encoders - 4.0 * 2.0 * (3.0 * enc - first)).abs() < 1.0);
        assert!(s.denoiser > 3.0 * 8.0 * blocks);
    }
}
