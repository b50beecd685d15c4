//! Where a model's weights come from while it is built: fresh, seeded initialisations (training),
//! a checkpoint's tensors (loading), or shapes only (counting parameters without allocating
//! them). Every layer asks a [`Builder`] for its tensors by PyTorch state-dict name, so the three
//! uses share one construction path and one naming.

use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

use candle_core::{DType, Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};

/// How a fresh tensor is initialised (PyTorch's `nn.init` functions of the same name).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Init {
    /// All zeros.
    Zeros,
    /// All ones.
    Ones,
    /// N(0, std²).
    Normal(f64),
    /// `xavier_uniform_` of a `[out, in]` matrix: U(±√(6 / (in + out))).
    XavierUniform,
    /// `kaiming_normal_(mode="fan_out", nonlinearity="relu")` of a conv kernel: N(0, 2 / fan_out).
    KaimingFanOut,
    /// PyTorch's default for Linear/Conv weights and biases: U(±1/√fan_in).
    FanInUniform(usize),
    /// DiT's 1-D sin-cos table over the second-to-last axis: row p is `[sin(p·ω), cos(p·ω)]`
    /// with ω_i = 10000^(−2i/d) for the last axis' d (even) values (the generator advances as
    /// for `Normal`, so the tensors after it start as they would after a learned one).
    SinCos,
}

/// One parameter: its state-dict name, its variable, and whether AdamW decays it.
#[derive(Clone, Debug)]
pub struct Param {
    /// PyTorch state-dict name.
    pub name: String,
    /// The variable (its tensor is what the model computes with).
    pub var: Var,
    /// Weight decay applies (Linear and Conv weights only).
    pub decay: bool,
    /// Never trained: the optimizer gets no gradient for it (a fixed table, PyTorch's
    /// `requires_grad=False`); saved and loaded as any other.
    pub frozen: bool,
}

enum Source {
    Fresh(Box<ChaCha8Rng>),
    Load {
        tensors: HashMap<String, Tensor>,
        file: String,
    },
    Shapes,
}

struct Inner {
    source: Source,
    device: Device,
    params: Vec<Param>,
    count: usize,
}

/// Hands out tensors under a dotted prefix; cheap to clone (the store is shared).
#[derive(Clone)]
pub(crate) struct Builder {
    inner: Rc<RefCell<Inner>>,
    prefix: String,
}

impl Builder {
    fn with(source: Source, device: &Device) -> Self {
        Builder {
            inner: Rc::new(RefCell::new(Inner {
                source,
                device: device.clone(),
                params: Vec::new(),
                count: 0,
            })),
            prefix: String::new(),
        }
    }

    /// Fresh weights from a seeded generator (the same seed gives the same weights anywhere).
    pub fn fresh(seed: u64, device: &Device) -> Self {
        Self::with(
            Source::Fresh(Box::new(ChaCha8Rng::seed_from_u64(seed))),
            device,
        )
    }

    /// Weights taken from `tensors` (read from `file`), each checked for its shape.
    pub fn load(tensors: HashMap<String, Tensor>, file: &str, device: &Device) -> Self {
        Self::with(
            Source::Load {
                tensors,
                file: file.to_string(),
            },
            device,
        )
    }

    /// No weights: every tensor is a broadcast zero of the right shape (one value allocated).
    pub fn shapes() -> Self {
        Self::with(Source::Shapes, &Device::Cpu)
    }

    /// The builder for the sub-module `name`.
    pub fn pp(&self, name: impl std::fmt::Display) -> Self {
        let prefix = if self.prefix.is_empty() {
            name.to_string()
        } else {
            format!("{}.{name}", self.prefix)
        };
        Builder {
            inner: self.inner.clone(),
            prefix,
        }
    }

    /// The tensor `name` of `shape`, created, loaded or shaped as this builder does.
    pub fn get(&self, shape: &[usize], name: &str, init: Init, decay: bool) -> Result<Tensor> {
        self.tensor(shape, name, init, decay, false)
    }

    /// As [`Builder::get`], for a tensor training leaves as it is ([`Param::frozen`]).
    pub fn get_fixed(&self, shape: &[usize], name: &str, init: Init) -> Result<Tensor> {
        self.tensor(shape, name, init, false, true)
    }

    fn tensor(
        &self,
        shape: &[usize],
        name: &str,
        init: Init,
        decay: bool,
        frozen: bool,
    ) -> Result<Tensor> {
        let full = if self.prefix.is_empty() {
            name.to_string()
        } else {
            format!("{}.{name}", self.prefix)
        };
        let mut inner = self.inner.borrow_mut();
        let n: usize = shape.iter().product();
        inner.count += n;
        let device = inner.device.clone();
        let tensor = match &mut inner.source {
            Source::Shapes => {
                return Ok(Tensor::zeros((), DType::F32, &device)?.broadcast_as(shape)?)
            }
            Source::Fresh(rng) => {
                let values = init_values(rng, shape, init);
                Tensor::from_vec(values, shape, &device)?
            }
            Source::Load { tensors, file } => {
                let t = tensors.remove(&full).ok_or_else(|| Error::Checkpoint {
                    path: file.clone(),
                    reason: format!("no tensor {full}"),
                })?;
                if t.dims() != shape {
                    return Err(Error::Checkpoint {
                        path: file.clone(),
                        reason: format!(
                            "{full} has shape {:?}, the model needs {shape:?}",
                            t.dims()
                        ),
                    });
                }
                t.to_dtype(DType::F32)?.to_device(&device)?
            }
        };
        let var = Var::from_tensor(&tensor)?;
        let t = var.as_tensor().clone();
        inner.params.push(Param {
            name: full,
            var,
            decay,
            frozen,
        });
        Ok(t)
    }

    /// The parameters created so far, in creation order, and the total count of values. A load
    /// fails here when the file holds tensors the model does not use.
    pub fn finish(self) -> Result<(Vec<Param>, usize)> {
        let mut inner = self.inner.borrow_mut();
        if let Source::Load { tensors, file } = &inner.source {
            if let Some(extra) = tensors.keys().min() {
                return Err(Error::Checkpoint {
                    path: file.clone(),
                    reason: format!(
                        "{} tensors the model does not have, e.g. {extra}",
                        tensors.len()
                    ),
                });
            }
        }
        Ok((std::mem::take(&mut inner.params), inner.count))
    }
}

fn init_values(rng: &mut ChaCha8Rng, shape: &[usize], init: Init) -> Vec<f32> {
    let n: usize = shape.iter().product();
    let uniform = |rng: &mut ChaCha8Rng, a: f64| -> Vec<f32> {
        (0..n).map(|_| rng.random_range(-a..a) as f32).collect()
    };
    match init {
        Init::Zeros => vec![0.0; n],
        Init::Ones => vec![1.0; n],
        Init::Normal(std) => normal(rng, n, std),
        Init::XavierUniform => {
            let (fan_out, fan_in) = fans(shape);
            uniform(rng, (6.0 / (fan_in + fan_out) as f64).sqrt())
        }
        Init::KaimingFanOut => {
            let (fan_out, _) = fans(shape);
            normal(rng, n, (2.0 / fan_out as f64).sqrt())
        }
        Init::FanInUniform(fan_in) => uniform(rng, 1.0 / (fan_in.max(1) as f64).sqrt()),
        Init::SinCos => {
            // Draw (and drop) what the learned embedding's N(0, 0.02) would, so every later
            // tensor starts as it does in the learned arm from the same seed.
            let _ = normal(rng, n, 0.02);
            sin_cos(shape)
        }
    }
}

/// [`Init::SinCos`] of `shape` (`[…, rows, d]`; leading axes repeat the table).
fn sin_cos(shape: &[usize]) -> Vec<f32> {
    let d = shape.last().copied().unwrap_or(1);
    let rows = shape.len().checked_sub(2).map_or(1, |i| shape[i]);
    let half = (d / 2).max(1);
    let table: Vec<f32> = (0..rows)
        .flat_map(|p| {
            (0..d).map(move |j| {
                let (i, sin) = if j < half {
                    (j, true)
                } else {
                    (j - half, false)
                };
                let a = p as f64 * 10000f64.powf(-(i as f64) / half as f64);
                (if sin { a.sin() } else { a.cos() }) as f32
            })
        })
        .collect();
    let n: usize = shape.iter().product();
    table.iter().copied().cycle().take(n).collect()
}

/// PyTorch's (fan_out, fan_in) of a weight `[out, in, *kernel]`.
fn fans(shape: &[usize]) -> (usize, usize) {
    let field: usize = shape.iter().skip(2).product();
    let out = shape.first().copied().unwrap_or(1);
    let inp = shape.get(1).copied().unwrap_or(1);
    (out * field, inp * field)
}

/// Box–Muller normals.
fn normal(rng: &mut ChaCha8Rng, n: usize, std: f64) -> Vec<f32> {
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt() * std;
        let th = 2.0 * std::f64::consts::PI * u2;
        out.push((r * th.cos()) as f32);
        out.push((r * th.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// A seeded standard-normal vector (noise, test weights).
pub(crate) fn randn(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    normal(rng, n, 1.0)
}
