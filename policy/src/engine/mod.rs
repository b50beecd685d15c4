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
pub(crate) mod encoder;
pub(crate) mod ops;
mod step;

use std::collections::HashMap;

use candle_core::{CpuStorage, Layout, Storage, StorageRef, Tensor};

use crate::error::{Error, Result};

pub(crate) use step::{Engine, Sampler};

/// The model's weights, read in place (a read lock on each tensor while the view lives).
pub(crate) struct WeightView<'a> {
    entries: HashMap<&'a str, (StorageRef<'a>, &'a Layout)>,
}

impl<'a> WeightView<'a> {
    /// A view of `weights` (name, CPU f32 tensor).
    pub fn new(weights: &'a [(String, Tensor)]) -> Self {
        WeightView {
            entries: weights
                .iter()
                .map(|(n, t)| (n.as_str(), t.storage_and_layout()))
                .collect(),
        }
    }

    /// Whether the model has a weight of that name.
    pub fn has(&self, name: &str) -> bool {
        self.entries.contains_key(name)
    }

    /// The values of weight `name`.
    pub fn get(&self, name: &str) -> Result<&[f32]> {
        let (s, l) = self
            .entries
            .get(name)
            .ok_or_else(|| Error::Config(format!("the model has no weight {name}")))?;
        let Storage::Cpu(CpuStorage::F32(v)) = &**s else {
            return Err(Error::Config(format!(
                "{name}: the CPU engine needs f32 weights on the CPU"
            )));
        };
        let (a, b) = l
            .contiguous_offsets()
            .ok_or_else(|| Error::Config(format!("{name}: weights must be contiguous")))?;
        Ok(&v[a..b])
    }

    /// The dims of weight `name`.
    pub fn shape(&self, name: &str) -> Result<Vec<usize>> {
        self.entries
            .get(name)
            .map(|(_, l)| l.dims().to_vec())
            .ok_or_else(|| Error::Config(format!("the model has no weight {name}")))
    }
}

/// Gradients by parameter name, summed over every use (and micro-batch).
#[derive(Default)]
pub(crate) struct Grads {
    map: HashMap<String, Vec<f32>>,
}

impl Grads {
    /// The buffer of `name` (`len` zeros when new).
    pub fn slot(&mut self, name: &str, len: usize) -> &mut [f32] {
        self.map
            .entry(name.to_string())
            .or_insert_with(|| vec![0.0; len])
    }

    /// Adds `g` to the gradient of `name`.
    pub fn add(&mut self, name: &str, g: &[f32]) {
        match self.map.get_mut(name) {
            Some(v) => ops::add_into(v, g),
            None => {
                self.map.insert(name.to_string(), g.to_vec());
            }
        }
    }

    /// Takes the gradient of `name`.
    pub fn take(&mut self, name: &str) -> Option<Vec<f32>> {
        self.map.remove(name)
    }
}

#[cfg(test)]
mod tests;
