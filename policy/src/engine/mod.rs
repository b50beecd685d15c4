//! The CPU engine: the whole model's forward and backward passes written out by hand, for
//! training and inference on the CPU. candle's autograd builds a graph of small ops, runs most
//! element-wise ones on one thread and allocates every intermediate; on a two-core machine a
//! ScaleDP-Ti step used about one core. Here every matrix product is one parallel GEMM (the
//! `gemm` crate candle itself multiplies with), every row op one parallel pass, and activations
//! live in buffers reused from step to step.
//!
//! The weights stay candle tensors (the optimizer, EMA, checkpoints and the CUDA path are
//! unchanged); a [`WeightView`] reads them in place, and the gradients come back by parameter
//! name ([`Grads`]). The candle modules remain the definition: the tests hold this engine's
//! outputs, loss and every gradient to theirs.

pub(crate) mod attention;
pub(crate) mod denoiser;
pub(crate) mod dpt;
pub(crate) mod encoder;
pub(crate) mod ops;
mod step;
mod weights;

pub(crate) use step::{Engine, Sampler};
pub(crate) use weights::{Grads, InOut, WeightView};

#[cfg(test)]
mod tests;
