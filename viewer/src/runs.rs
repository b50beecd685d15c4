//! Training curves ([`TrainingView`], for `scaledp train --view`) and policy rollouts with
//! their predicted chunks ([`RolloutView`], for `eval --view` / `predict --view`), each on its
//! own recording at a [`Target`].

use std::path::PathBuf;

use rerun::{Scalars, SeriesLines, TextLog};
use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;

use crate::arm::ArmModel;
use crate::error::{Error, Result};
use crate::images::{raw_frame, Frame};
use crate::layout;
use crate::live::{now_ns, Own};
#[allow(unused_imports)] // for the docs' links
use crate::sink::Target;
use crate::space::Dims;

/// A training run's curves on a `step` timeline (for `scaledp train --view`).
///
/// ```no_run
/// # fn main() -> scaledp_viewer::Result<()> {
/// use scaledp_viewer::{Target, TrainingView};
/// let view = TrainingView::start(&Target::Spawn, "scaledp-s cups")?;
/// for step in 0..1000u64 {
///     view.log_step(step, 0.1, 1e-4)?;
/// }
/// view.log_validation(1000, "action_mse", 0.02)?;
/// view.finish()?;
/// # Ok(()) }
/// ```
pub struct TrainingView {
    own: Own,
}

impl TrainingView {
    /// Opens a recording named `run` at `target`.
    pub fn start(target: &Target, run: &str) -> Result<Self> {
        let own = Own::open(
            target,
            &format!("train-{run}-{}", now_ns()),
            &format!("train: {run}"),
        )?;
        own.rec()?
            .log_static("train/loss", &SeriesLines::new().with_names(["loss"]))
            .map_err(Error::rerun)?;
        Ok(Self { own })
    }

    /// The training loss and learning rate at `step` (`train/loss`, `train/lr`).
    pub fn log_step(&self, step: u64, loss: f64, lr: f64) -> Result<()> {
        self.log_scalar(step, "train/loss", loss)?;
        self.log_scalar(step, "train/lr", lr)
    }

    /// A validation figure at `step` (`val/<name>`, e.g. `val/loss`, `val/action_mse`).
    pub fn log_validation(&self, step: u64, name: &str, value: f64) -> Result<()> {
        self.log_scalar(step, &format!("val/{name}"), value)
    }

    /// Any scalar at `step` under `entity`.
    pub fn log_scalar(&self, step: u64, entity: &str, value: f64) -> Result<()> {
        let rec = self.own.rec()?;
        rec.set_time_sequence(layout::STEP, step as i64);
        rec.log(entity, &Scalars::new([value]))
            .map_err(Error::rerun)
    }

    /// Flushes; returns the `.rrd` written with [`Target::Save`].
    pub fn finish(self) -> Result<Option<PathBuf>> {
        self.own.finish()
    }
}

/// Policy rollouts (for `scaledp eval --view` / `predict --view`): camera images, the state,
/// the action executed and each predicted chunk, per arm in 3-D, on `step` and `time` timelines.
pub struct RolloutView {
    own: Own,
    rig: Rig,
    arms: Vec<Option<ArmModel>>,
    dims: Dims,
}

impl RolloutView {
    /// Opens a recording named `name` for rollouts of `rig` at `target`, its state and action
    /// in `space`.
    pub fn start(target: &Target, name: &str, rig: &Rig, space: ActionSpace) -> Result<Self> {
        let dims = Dims::new(rig, space);
        let own = Own::open(target, &format!("rollout-{name}-{}", now_ns()), name)?;
        let arms: Vec<Option<ArmModel>> = rig.arms.iter().map(|a| ArmModel::new(a).ok()).collect();
        let r = Error::rerun;
        let rec = own.rec()?;
        rec.log_static(layout::WORLD, &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())
            .map_err(r)?;
        for (i, m) in arms.iter().enumerate() {
            if let Some(m) = m {
                m.log_static(rec, i, arms.len())?;
            }
            for d in &dims.arms[i].labels {
                rec.log_static(
                    layout::state_action(space, &rig.arms[i].name, d),
                    &SeriesLines::new().with_names(["state", "action"]),
                )
                .map_err(r)?;
            }
        }
        Ok(Self {
            own,
            rig: rig.clone(),
            arms,
            dims,
        })
    }

    /// Sets the time of what follows: control step and seconds since the rollout began.
    pub fn set_time(&self, step: u64, time_s: f64) {
        if let Ok(rec) = self.own.rec() {
            rec.set_time_sequence(layout::STEP, step as i64);
            rec.set_duration_secs(layout::TIMESTAMP, time_s);
        }
    }

    /// A camera image, packed RGB8 rows (`width × height × 3` bytes).
    pub fn log_image(&self, camera: &str, rgb: &[u8], width: u32, height: u32) -> Result<()> {
        let view = scaledp_converter::images::ImageView {
            width,
            height,
            encoding: "rgb8",
            step: width * 3,
            data: rgb,
        };
        let frame: Frame = raw_frame(&view, None).map_err(|e| Error::input(camera, e))?;
        frame
            .log(self.own.rec()?, &layout::camera(camera))
            .map_err(Error::rerun)
    }

    /// The state and the action executed (per arm, rig order, in the view's space, like a
    /// dataset's), and the joint positions (rig order, arm joints only) when known, for the
    /// 3-D arms.
    pub fn log_step(&self, state: &[f32], action: &[f32], joints: Option<&[f64]>) -> Result<()> {
        let r = Error::rerun;
        let rec = self.own.rec()?;
        let mut offset = 0;
        for (i, arm) in self.rig.arms.iter().enumerate() {
            let a = &self.dims.arms[i];
            for (d, dim) in a.labels.iter().enumerate() {
                let k = a.range.start + d;
                let v = |x: &[f32]| x.get(k).map_or(f64::NAN, |&v| f64::from(v));
                rec.log(
                    layout::state_action(self.dims.space, &arm.name, dim),
                    &Scalars::new([v(state), v(action)]),
                )
                .map_err(r)?;
            }
            let n = arm.joint_names.len();
            if let (Some(q), Some(Some(m))) = (
                joints.and_then(|j| j.get(offset..offset + n)),
                self.arms.get(i),
            ) {
                m.log_pose(rec, q)?;
            }
            offset += n;
        }
        Ok(())
    }

    /// A predicted chunk: `dim` values per step (per arm, rig order, in the view's space),
    /// drawn per arm as a line strip through its TCP positions.
    pub fn log_chunk(&self, predicted: &[f32], dim: usize) -> Result<()> {
        if dim == 0 {
            return Ok(());
        }
        let rows: Vec<Vec<f32>> = predicted.chunks(dim).map(<[f32]>::to_vec).collect();
        for (i, arm) in self.rig.arms.iter().enumerate() {
            let strip = self.dims.tcp_strip(&rows, i);
            self.own
                .rec()?
                .log(
                    layout::predicted_chunk(&arm.name),
                    &rerun::LineStrips3D::new([strip])
                        .with_radii([0.004])
                        .with_colors([0x1e90ffffu32]),
                )
                .map_err(Error::rerun)?;
        }
        Ok(())
    }

    /// A line in the text log (success, failure, reset…).
    pub fn log_text(&self, text: &str) -> Result<()> {
        self.own
            .rec()?
            .log(layout::LOG, &TextLog::new(text))
            .map_err(Error::rerun)
    }

    /// Flushes; returns the `.rrd` written with [`Target::Save`].
    pub fn finish(self) -> Result<Option<PathBuf>> {
        self.own.finish()
    }
}
