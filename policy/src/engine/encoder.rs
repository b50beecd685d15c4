//! One camera's encoder — ResNet-18 trunk with GroupNorm, SpatialSoftmax, Linear — forward and
//! backward by hand on channels-last activations, with the fused kernels of
//! [`crate::model::conv`] and [`crate::model::fused`]. Activations live in buffers reused from
//! step to step; the arithmetic is the candle module's ([`crate::model::encoder`]).

use rayon::prelude::*;

use super::ops::{self, linear, linear_backward};
use super::{Grads, WeightView};
use crate::error::Result;
use crate::model::conv::{self, Geom};
use crate::model::fused::{self, Dims};

/// GroupNorm's epsilon (PyTorch's default).
const GN_EPS: f64 = 1e-5;

/// A convolution's weights reordered for the kernels, and its geometry for this batch.
struct ConvAt {
    name: String,
    geom: Geom,
    /// `[C_out, kh, kw, C_in]`, or `[kh, kw, C_in, C_out]` when `hwio` (sampling only).
    wp: std::sync::Arc<[f32]>,
    hwio: bool,
}

impl ConvAt {
    fn new(wv: &WeightView, name: String, input: [usize; 4], stride: usize) -> Result<Self> {
        let shape = wv.shape(&name)?;
        let padding = shape[2] / 2;
        let geom = Geom::new(&input, &shape, stride, padding)?;
        let (wp, hwio) = wv.conv_kernel(&name, &geom)?;
        Ok(ConvAt {
            name,
            geom,
            wp,
            hwio,
        })
    }
    fn out_dims(&self) -> [usize; 4] {
        let g = &self.geom;
        [g.b, g.out_h(), g.out_w(), g.c_out]
    }
    fn out_len(&self) -> usize {
        self.out_dims().iter().product()
    }
    fn forward(&self, x: &[f32], y: &mut Vec<f32>) {
        y.resize(self.out_len(), 0.0);
        conv::forward(&self.geom, x, &self.wp, self.hwio, y);
    }
    /// Adds dW to `grads`; `dx` gets the input gradient when given (`acc`: added to it).
    fn backward(
        &self,
        grads: &mut Grads,
        x: &[f32],
        dy: &[f32],
        dx: Option<(&mut Vec<f32>, bool)>,
    ) {
        debug_assert!(!self.hwio, "sampling kernels have no backward");
        let g = &self.geom;
        let mut dwp = vec![0f32; g.c_out * g.k()];
        conv::grad_weight(g, x, dy, &mut dwp);
        grads.add(&self.name, &conv::ohwi_to_oihw(g, &dwp));
        if let Some((dx, acc)) = dx {
            if !acc {
                dx.resize(g.b * g.per_in(), 0.0);
            }
            conv::grad_input(g, dy, &self.wp, dx, acc);
        }
    }
}

/// A GroupNorm (C/16 groups) under `name`.
struct Norm {
    name: String,
    dims: Dims,
}

impl Norm {
    fn new(name: String, out: [usize; 4]) -> Self {
        let c = out[3];
        Norm {
            name,
            dims: Dims {
                n: out[0],
                s: out[1] * out[2],
                c,
                g: (c / 16).max(1),
            },
        }
    }
    fn forward(&self, wv: &WeightView, x: &[f32], relu: bool, y: &mut Vec<f32>) -> Result<()> {
        y.resize(x.len(), 0.0);
        let (gw, gb) = (
            wv.get(&format!("{}.weight", self.name))?,
            wv.get(&format!("{}.bias", self.name))?,
        );
        fused::group_norm_forward(&self.dims, x, gw, gb, GN_EPS, relu, y);
        Ok(())
    }
    /// `dx` (overwritten) from the norm's input `x` and `dy`; dγ, dβ added to `grads`.
    fn backward(
        &self,
        wv: &WeightView,
        grads: &mut Grads,
        x: &[f32],
        dy: &[f32],
        relu: bool,
        dx: &mut Vec<f32>,
    ) -> Result<()> {
        let (wn, bn) = (
            format!("{}.weight", self.name),
            format!("{}.bias", self.name),
        );
        let (gw, gb) = (wv.get(&wn)?, wv.get(&bn)?);
        dx.resize(x.len(), 0.0);
        let c = self.dims.c;
        let (mut dg, mut db) = (vec![0f32; c], vec![0f32; c]);
        fused::group_norm_backward(
            &self.dims, x, dy, gw, gb, GN_EPS, relu, dx, &mut dg, &mut db, false,
        );
        grads.add(&wn, &dg);
        grads.add(&bn, &db);
        Ok(())
    }
}

/// One residual block's layers and activations.
struct Block {
    conv1: ConvAt,
    bn1: Norm,
    conv2: ConvAt,
    bn2: Norm,
    down: Option<(ConvAt, Norm)>,
    c1: Vec<f32>,
    a1: Vec<f32>,
    c2: Vec<f32>,
    b2: Vec<f32>,
    cd: Vec<f32>,
    sd: Vec<f32>,
    y: Vec<f32>,
}

/// The trunk's activations after a forward pass, kept for the backward.
#[derive(Default)]
pub(crate) struct Work {
    prefix: String,
    input: Vec<f32>,
    stem: Option<(ConvAt, Norm)>,
    s_conv: Vec<f32>,
    s_act: Vec<f32>,
    pooled: Vec<f32>,
    pool_dims: (usize, usize, usize),
    blocks: Vec<Block>,
    /// SpatialSoftmax: logits → probabilities `[N, K, P]`, keypoints `[N, 2K]`.
    probs: Vec<f32>,
    keypoints: Vec<f32>,
    map_dims: (usize, usize, usize),
    /// The encoder's output `[N, F]`.
    pub out: Vec<f32>,
}

/// linspace(−1, 1, n)[i], as the candle module's grid.
fn lin(i: usize, n: usize) -> f32 {
    if n <= 1 {
        -1.0
    } else {
        (-1.0 + 2.0 * i as f64 / (n - 1) as f64) as f32
    }
}

impl Work {
    /// Runs the encoder under `prefix` (`obs_encoder.<camera>`) on `n` channels-last images
    /// `input` `[n, h, w, 3]` (already cropped and scaled), keeping what the backward needs.
    pub fn forward(
        &mut self,
        wv: &WeightView,
        prefix: &str,
        input: Vec<f32>,
        (n, h, w): (usize, usize, usize),
    ) -> Result<()> {
        self.prefix = prefix.to_string();
        self.input = input;
        let bb = format!("{prefix}.backbone");
        let conv1 = ConvAt::new(wv, format!("{bb}.conv1.weight"), [n, h, w, 3], 2)?;
        let bn1 = Norm::new(format!("{bb}.bn1"), conv1.out_dims());
        conv1.forward(&self.input, &mut self.s_conv);
        bn1.forward(wv, &self.s_conv, true, &mut self.s_act)?;
        let [_, sh, sw, sc] = conv1.out_dims();
        self.pool_dims = (sh, sw, sc);
        let (ph, pw) = (fused::pooled(sh), fused::pooled(sw));
        self.pooled.resize(n * ph * pw * sc, 0.0);
        fused::max_pool_forward(self.pool_dims, &self.s_act, &mut self.pooled);
        self.stem = Some((conv1, bn1));
        let mut dims = [n, ph, pw, sc];
        let mut blocks = std::mem::take(&mut self.blocks);
        let mut k = 0;
        for stage in 0..4 {
            for idx in 0..2 {
                let stride = if stage > 0 && idx == 0 { 2 } else { 1 };
                let p = format!("{bb}.layer{}.{idx}", stage + 1);
                let conv1 = ConvAt::new(wv, format!("{p}.conv1.weight"), dims, stride)?;
                let bn1 = Norm::new(format!("{p}.bn1"), conv1.out_dims());
                let conv2 = ConvAt::new(wv, format!("{p}.conv2.weight"), conv1.out_dims(), 1)?;
                let bn2 = Norm::new(format!("{p}.bn2"), conv2.out_dims());
                let down = if wv.has(&format!("{p}.downsample.0.weight")) {
                    let c = ConvAt::new(wv, format!("{p}.downsample.0.weight"), dims, stride)?;
                    let nrm = Norm::new(format!("{p}.downsample.1"), c.out_dims());
                    Some((c, nrm))
                } else {
                    None
                };
                let mut b = match blocks.get_mut(k) {
                    Some(old) => Block {
                        conv1,
                        bn1,
                        conv2,
                        bn2,
                        down,
                        c1: std::mem::take(&mut old.c1),
                        a1: std::mem::take(&mut old.a1),
                        c2: std::mem::take(&mut old.c2),
                        b2: std::mem::take(&mut old.b2),
                        cd: std::mem::take(&mut old.cd),
                        sd: std::mem::take(&mut old.sd),
                        y: std::mem::take(&mut old.y),
                    },
                    None => Block {
                        conv1,
                        bn1,
                        conv2,
                        bn2,
                        down,
                        c1: Vec::new(),
                        a1: Vec::new(),
                        c2: Vec::new(),
                        b2: Vec::new(),
                        cd: Vec::new(),
                        sd: Vec::new(),
                        y: Vec::new(),
                    },
                };
                let x: &[f32] = if k == 0 {
                    &self.pooled
                } else {
                    &blocks[k - 1].y
                };
                b.conv1.forward(x, &mut b.c1);
                b.bn1.forward(wv, &b.c1, true, &mut b.a1)?;
                b.conv2.forward(&b.a1, &mut b.c2);
                b.bn2.forward(wv, &b.c2, false, &mut b.b2)?;
                let skip: &[f32] = match &b.down {
                    Some((c, nrm)) => {
                        c.forward(x, &mut b.cd);
                        nrm.forward(wv, &b.cd, false, &mut b.sd)?;
                        &b.sd
                    }
                    None => x,
                };
                b.y.resize(b.b2.len(), 0.0);
                fused::add_relu_forward(&b.b2, skip, &mut b.y);
                dims = b.conv2.out_dims();
                if k < blocks.len() {
                    blocks[k] = b;
                } else {
                    blocks.push(b);
                }
                k += 1;
            }
        }
        blocks.truncate(k);
        self.blocks = blocks;
        self.spatial_softmax_forward(wv, dims)
    }

    fn spatial_softmax_forward(&mut self, wv: &WeightView, [n, h, w, c]: [usize; 4]) -> Result<()> {
        let prefix = &self.prefix;
        let kw = wv.get(&format!("{prefix}.pool.nets.weight"))?;
        let kb = wv.get(&format!("{prefix}.pool.nets.bias"))?;
        let k = kb.len();
        let p = h * w;
        self.map_dims = (h, w, k);
        let feat = &self.blocks[self.blocks.len() - 1].y;
        let mut logits = vec![0f32; n * p * k];
        linear(feat, kw, Some(kb), n * p, c, k, &mut logits);
        self.probs.resize(n * k * p, 0.0);
        self.keypoints.resize(n * 2 * k, 0.0);
        self.probs
            .par_chunks_mut(k * p)
            .zip(self.keypoints.par_chunks_mut(2 * k))
            .zip(logits.par_chunks(p * k))
            .for_each(|((pr, kp), lg)| {
                for j in 0..k {
                    let row = &mut pr[j * p..(j + 1) * p];
                    let mut max = f32::NEG_INFINITY;
                    for (q, r) in row.iter_mut().enumerate() {
                        *r = lg[q * k + j];
                        max = max.max(*r);
                    }
                    let mut sum = 0f32;
                    for r in row.iter_mut() {
                        *r = (*r - max).exp();
                        sum += *r;
                    }
                    let (mut ex, mut ey) = (0f32, 0f32);
                    for (q, r) in row.iter_mut().enumerate() {
                        *r /= sum;
                        ex += *r * lin(q % w, w);
                        ey += *r * lin(q / w, h);
                    }
                    kp[2 * j] = ex;
                    kp[2 * j + 1] = ey;
                }
            });
        let lw = wv.get(&format!("{prefix}.linear.weight"))?;
        let lb = wv.get(&format!("{prefix}.linear.bias"))?;
        let f = lb.len();
        self.out.resize(n * f, 0.0);
        linear(&self.keypoints, lw, Some(lb), n, 2 * k, f, &mut self.out);
        Ok(())
    }

    /// The backward of the last [`Work::forward`] from `dout` `[N, F]`: every parameter's
    /// gradient added to `grads` (the images get none).
    pub fn backward(&mut self, wv: &WeightView, grads: &mut Grads, dout: &[f32]) -> Result<()> {
        let prefix = self.prefix.clone();
        let (h, w, k) = self.map_dims;
        let p = h * w;
        let n = self.keypoints.len() / (2 * k);
        // Linear.
        let (lwn, lbn) = (
            format!("{prefix}.linear.weight"),
            format!("{prefix}.linear.bias"),
        );
        let lw = wv.get(&lwn)?;
        let f = lw.len() / (2 * k);
        let mut dkp = vec![0f32; n * 2 * k];
        let (mut dlw, mut dlb) = (vec![0f32; f * 2 * k], vec![0f32; f]);
        linear_backward(
            &self.keypoints,
            lw,
            dout,
            n,
            2 * k,
            f,
            &mut dlw,
            Some(&mut dlb),
            Some((&mut dkp, false)),
        );
        grads.add(&lwn, &dlw);
        grads.add(&lbn, &dlb);
        // SpatialSoftmax: dα = dkx·gx + dky·gy; dlogit = α (dα − Σ α dα).
        let mut dlogits = vec![0f32; n * p * k];
        dlogits
            .par_chunks_mut(p * k)
            .zip(self.probs.par_chunks(k * p).zip(dkp.par_chunks(2 * k)))
            .for_each(|(dl, (pr, dk))| {
                for j in 0..k {
                    let row = &pr[j * p..(j + 1) * p];
                    let (gx, gy) = (dk[2 * j], dk[2 * j + 1]);
                    let mut dot = 0f32;
                    for (q, a) in row.iter().enumerate() {
                        dot += a * (gx * lin(q % w, w) + gy * lin(q / w, h));
                    }
                    for (q, a) in row.iter().enumerate() {
                        let da = gx * lin(q % w, w) + gy * lin(q / w, h);
                        dl[q * k + j] = a * (da - dot);
                    }
                }
            });
        let (kwn, kbn) = (
            format!("{prefix}.pool.nets.weight"),
            format!("{prefix}.pool.nets.bias"),
        );
        let kw = wv.get(&kwn)?;
        let c = kw.len() / k;
        let feat = &self.blocks[self.blocks.len() - 1].y;
        let mut dfeat = vec![0f32; n * p * c];
        let (mut dkw, mut dkb) = (vec![0f32; k * c], vec![0f32; k]);
        linear_backward(
            feat,
            kw,
            &dlogits,
            n * p,
            c,
            k,
            &mut dkw,
            Some(&mut dkb),
            Some((&mut dfeat, false)),
        );
        grads.add(&kwn, &dkw);
        grads.add(&kbn, &dkb);
        // Blocks, last first: dy is the gradient of the block's output.
        let mut dy = dfeat;
        let (mut g, mut t1, mut t2) = (Vec::new(), Vec::new(), Vec::new());
        for i in (0..self.blocks.len()).rev() {
            let (before, rest) = self.blocks.split_at(i);
            let b = &rest[0];
            let x: &[f32] = if i == 0 {
                &self.pooled
            } else {
                &before[i - 1].y
            };
            g.resize(b.y.len(), 0.0);
            fused::relu_backward(&b.y, &dy, &mut g);
            // Main path: bn2 ← conv2 ← bn1+relu ← conv1.
            b.bn2.backward(wv, grads, &b.c2, &g, false, &mut t1)?;
            b.conv2.backward(grads, &b.a1, &t1, Some((&mut t2, false)));
            b.bn1.backward(wv, grads, &b.c1, &t2, true, &mut t1)?;
            let mut dx = Vec::new();
            b.conv1.backward(grads, x, &t1, Some((&mut dx, false)));
            // Skip path.
            match &b.down {
                Some((cv, nrm)) => {
                    nrm.backward(wv, grads, &b.cd, &g, false, &mut t1)?;
                    cv.backward(grads, x, &t1, Some((&mut dx, true)));
                }
                None => ops::add_into(&mut dx, &g),
            }
            dy = dx;
        }
        // Stem: max-pool ← bn1+relu ← conv1 (no gradient for the images).
        let (conv1, bn1) = self
            .stem
            .as_ref()
            .ok_or_else(|| crate::error::Error::Config("encoder backward before forward".into()))?;
        let mut dact = vec![0f32; self.s_act.len()];
        fused::max_pool_backward(self.pool_dims, &self.s_act, &dy, &mut dact);
        bn1.backward(wv, grads, &self.s_conv, &dact, true, &mut t1)?;
        conv1.backward(grads, &self.input, &t1, None);
        Ok(())
    }
}
