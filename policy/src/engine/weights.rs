//! The weights as the engine reads them (in place, with `[in, out]` copies for inference)
//! and the gradients it hands back by parameter name.

use std::collections::HashMap;
use std::sync::Arc;

use candle_core::{CpuStorage, Layout, Storage, StorageRef, Tensor};

use super::ops;
use crate::error::{Error, Result};
use crate::model::conv::{kernel_to_ohwi, transposed};

/// The model's weights, read in place (a read lock on each tensor while the view lives), and
/// for inference `[in, out]` copies of the Linear weights ([`InOut`]).
pub(crate) struct WeightView<'a> {
    entries: HashMap<&'a str, (StorageRef<'a>, &'a Layout)>,
    in_out: Option<&'a InOut>,
}

/// `[in, out]` copies of a model's 2-D weights (Linear layers), made once for a model whose
/// weights no longer change (a loaded policy): see [`ops::LinearWeight`]. Remembers which
/// tensors it copied, so a different model is noticed.
/// The convolutions' kernels are kept reordered `[kh, kw, C_in, C_out]` the same way.
#[derive(Default)]
pub(crate) struct InOut {
    of: Vec<candle_core::TensorId>,
    map: HashMap<String, Vec<f32>>,
    hwio: HashMap<String, Arc<[f32]>>,
}

impl InOut {
    /// Whether these are the copies of `weights`.
    pub fn is_of(&self, weights: &[(String, Tensor)]) -> bool {
        self.of.len() == weights.len()
            && self.of.iter().zip(weights).all(|(a, (_, t))| *a == t.id())
    }

    /// `[in, out]` copies of every 2-D weight named `*.weight` among `weights`.
    pub fn of(weights: &[(String, Tensor)]) -> Result<Self> {
        let view = WeightView::new(weights);
        let (mut map, mut hwio) = (HashMap::new(), HashMap::new());
        for (name, t) in weights {
            if !name.ends_with(".weight") {
                continue;
            }
            if let &[co, ci, kh, kw] = t.dims() {
                let k = kernel_to_ohwi(ci, kh * kw, view.get(name)?);
                hwio.insert(name.clone(), Arc::from(transposed(co, ci * kh * kw, &k)));
                continue;
            }
            let &[out, inp] = t.dims() else { continue };
            let w = view.get(name)?;
            map.insert(name.clone(), transposed(out, inp, w));
            // DP-T's cross-attention projects queries and the memory's keys and values apart:
            // copies of its query rows and of its key/value rows.
            if name.ends_with("multihead_attn.in_proj_weight") && out == 3 * inp {
                for (from, n) in [(0, inp), (inp, 2 * inp)] {
                    let part = &w[from * inp..(from + n) * inp];
                    map.insert(rows_key(name, from, n), transposed(n, inp, part));
                }
            }
        }
        Ok(InOut {
            of: weights.iter().map(|(_, t)| t.id()).collect(),
            map,
            hwio,
        })
    }
}

impl<'a> WeightView<'a> {
    /// A view of `weights` (name, CPU f32 tensor).
    pub fn new(weights: &'a [(String, Tensor)]) -> Self {
        WeightView {
            entries: weights
                .iter()
                .map(|(n, t)| (n.as_str(), t.storage_and_layout()))
                .collect(),
            in_out: None,
        }
    }

    /// The view, multiplying Linear layers by the `[in, out]` copies in `c`.
    pub fn with_in_out(mut self, c: &'a InOut) -> Self {
        self.in_out = Some(c);
        self
    }

    /// Convolution kernel `name` (of geometry `g`) reordered `[C_out, kh, kw, C_in]`, or its
    /// `[kh, kw, C_in, C_out]` copy when the view has one (`.1` is then true).
    pub fn conv_kernel(
        &self,
        name: &str,
        g: &crate::model::conv::Geom,
    ) -> Result<(Arc<[f32]>, bool)> {
        match self.in_out.and_then(|c| c.hwio.get(name)) {
            Some(k) => Ok((k.clone(), true)),
            None => Ok((
                crate::model::conv::oihw_to_ohwi(g, self.get(name)?).into(),
                false,
            )),
        }
    }

    /// Linear weight `name` for a forward pass: its `[in, out]` copy when the view has one.
    pub fn linear(&self, name: &str) -> Result<ops::LinearWeight<'_>> {
        match self.in_out.and_then(|c| c.map.get(name)) {
            Some(v) => Ok(ops::LinearWeight {
                values: v,
                in_out: true,
            }),
            None => self.get(name).map(ops::LinearWeight::from),
        }
    }

    /// Rows `from .. from + n` of the `[out, in]` weight `name` as a Linear weight of `n` outputs
    /// (its `[in, n]` copy when the view has one).
    pub fn linear_rows(&self, name: &str, from: usize, n: usize) -> Result<ops::LinearWeight<'_>> {
        if let Some(v) = self
            .in_out
            .and_then(|c| c.map.get(&rows_key(name, from, n)))
        {
            return Ok(ops::LinearWeight {
                values: v,
                in_out: true,
            });
        }
        let inp = self.shape(name)?.get(1).copied().unwrap_or(1);
        let w = self.get(name)?;
        w.get(from * inp..(from + n) * inp)
            .map(ops::LinearWeight::from)
            .ok_or_else(|| Error::Config(format!("{name} has no rows {from}..{}", from + n)))
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

/// The key of rows `from .. from + n` of weight `name` among [`InOut`]'s copies.
fn rows_key(name: &str, from: usize, n: usize) -> String {
    format!("{name}[{from}..{}]", from + n)
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
