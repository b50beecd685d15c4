//! Normalization of state and action vectors from `meta/stats.json`, exposed so a trainer can
//! un-normalize what its policy predicts.

use std::collections::BTreeMap;

use crate::error::{Error, Result};

/// How a feature is normalized.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Norm {
    /// `2 (x − min) / (max − min) − 1`: [-1, 1] over the dataset's range (actions). A
    /// dimension whose range is under 1e-4 (a gripper never used) is only centred, `x − min`,
    /// as diffusion_policy's `LinearNormalizer` does, so a small deviation at deployment stays
    /// small instead of being multiplied by 2·10⁴.
    MinMax,
    /// `(x − mean) / (std + 1e-8)` (state); a dimension whose std is under 1e-4 is only
    /// centred, `x − mean`.
    MeanStd,
    /// Values as stored.
    #[default]
    None,
}

/// Ranges (and standard deviations) below this are not scaled, as diffusion_policy's
/// `range_eps`.
pub const MIN_MAX_EPS: f64 = 1e-4;
/// Added to the standard deviation by [`Norm::MeanStd`].
pub const MEAN_STD_EPS: f64 = 1e-8;

/// `y = x · scale + offset` per dimension.
#[derive(Clone, Debug, PartialEq)]
pub struct Affine {
    /// The mode it was built from.
    pub norm: Norm,
    scale: Vec<f64>,
    offset: Vec<f64>,
}

impl Affine {
    /// Builds the transform of `feature` from its statistics.
    pub fn new(
        norm: Norm,
        feature: &str,
        dim: usize,
        stats: &BTreeMap<String, BTreeMap<String, Vec<f64>>>,
        stats_file: &str,
    ) -> Result<Self> {
        let get = |name: &str| -> Result<&Vec<f64>> {
            let v = stats
                .get(feature)
                .and_then(|s| s.get(name))
                .ok_or_else(|| {
                    Error::format(stats_file, format!("no {feature}/{name} to normalize with"))
                })?;
            if v.len() != dim {
                return Err(Error::format(
                    stats_file,
                    format!("{feature}/{name} has {} values, the feature {dim}", v.len()),
                ));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(Error::format(
                    stats_file,
                    format!("{feature}/{name}[{i}] is {}, not a finite number", v[i]),
                ));
            }
            Ok(v)
        };
        let (scale, offset) = match norm {
            Norm::None => (vec![1.0; dim], vec![0.0; dim]),
            Norm::MinMax => {
                let (min, max) = (get("min")?, get("max")?);
                min.iter()
                    .zip(max)
                    .map(|(lo, hi)| match hi - lo {
                        r if r >= MIN_MAX_EPS => (2.0 / r, -1.0 - lo * 2.0 / r),
                        _ => (1.0, -lo),
                    })
                    .unzip()
            }
            Norm::MeanStd => {
                let (mean, std) = (get("mean")?, get("std")?);
                mean.iter()
                    .zip(std)
                    .map(|(m, s)| match 1.0 / (s + MEAN_STD_EPS) {
                        k if *s >= MIN_MAX_EPS => (k, -m * k),
                        _ => (1.0, -m),
                    })
                    .unzip()
            }
        };
        Ok(Affine {
            norm,
            scale,
            offset,
        })
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.scale.len()
    }

    /// Per-dimension scale: normalized = raw · scale + offset.
    pub fn scale(&self) -> &[f64] {
        &self.scale
    }

    /// Per-dimension offset: normalized = raw · scale + offset.
    pub fn offset(&self) -> &[f64] {
        &self.offset
    }

    /// Normalizes rows of `dim` values in place.
    pub fn apply(&self, x: &mut [f32]) {
        for row in x.chunks_mut(self.dim().max(1)) {
            for ((v, s), o) in row.iter_mut().zip(&self.scale).zip(&self.offset) {
                *v = (f64::from(*v) * s + o) as f32;
            }
        }
    }

    /// Undoes [`Affine::apply`].
    pub fn invert(&self, x: &mut [f32]) {
        for row in x.chunks_mut(self.dim().max(1)) {
            for ((v, s), o) in row.iter_mut().zip(&self.scale).zip(&self.offset) {
                *v = ((f64::from(*v) - o) / s) as f32;
            }
        }
    }
}

/// The state and action normalizations a loader applies.
#[derive(Clone, Debug)]
pub struct Normalizer {
    /// Of `observation.state`.
    pub state: Affine,
    /// Of `action`.
    pub action: Affine,
}

impl Normalizer {
    /// Normalizes rows of state values in place.
    pub fn normalize_state(&self, x: &mut [f32]) {
        self.state.apply(x);
    }
    /// Un-normalizes rows of state values in place.
    pub fn unnormalize_state(&self, x: &mut [f32]) {
        self.state.invert(x);
    }
    /// Normalizes rows of action values in place.
    pub fn normalize_action(&self, x: &mut [f32]) {
        self.action.apply(x);
    }
    /// Un-normalizes rows of action values (a policy's prediction) in place.
    pub fn unnormalize_action(&self, x: &mut [f32]) {
        self.action.invert(x);
    }
}
