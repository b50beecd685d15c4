//! An episode as training data: per frame the state and action of each arm (one plot per
//! dimension, state and action together), each arm in 3-D (links, chain, TCP, trajectory, the
//! action chunk ahead), and, for recordings, the converter's quality signals per tick.
//! Recordings get their frames from the converter itself (alignment and state exactly as
//! `scaledp convert` computes them); datasets from their stored columns.

use rerun::{LineStrips3D, RecordingStream, Scalars, SeriesLines, SeriesPoints, TextLog};
use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;
use std::collections::BTreeMap;

use crate::arm::ArmModel;
use crate::error::{Error, Result};
use crate::layout;
use crate::space::Dims;

/// Frames of an episode: state and action rows, and joint positions when stored.
#[derive(Debug, Default, Clone)]
pub(crate) struct Rows {
    /// Names of the state dimensions.
    pub state_names: Vec<String>,
    /// Names of the action dimensions.
    pub action_names: Vec<String>,
    /// Per frame.
    pub state: Vec<Vec<f32>>,
    /// Per frame.
    pub action: Vec<Vec<f32>>,
    /// Names of the joint dimensions (empty without joints).
    pub joint_names: Vec<String>,
    /// Per frame (empty without joints).
    pub joints: Vec<Vec<f32>>,
    /// Also plot `joints` (and the gripper opening they give) per frame: for datasets, whose
    /// joint positions exist only at the frames (a recording plots every message instead).
    pub plot_joints: bool,
    /// Per frame, a policy's predicted chunk (C × the action's values) when one is shown.
    pub predicted: Vec<Option<Vec<f32>>>,
    /// The space of the state and action.
    pub space: ActionSpace,
}

/// One plotted pair: entity, state index, action index.
type Pair = (String, Option<usize>, Option<usize>);

/// Which entity each state and action dimension goes to: per arm of the rig (rig order) its
/// dimensions in the rows' space ([`layout::state_action`]), else `pose/<name>` with state and
/// action matched by name.
fn pairs(rows: &Rows, rig: Option<&Rig>, dims: Option<&Dims>) -> Vec<Pair> {
    if let (Some(rig), Some(dims)) = (rig, dims.filter(|d| d.fits(rows.state_names.len()))) {
        let mut out = Vec::new();
        for (arm, a) in rig.arms.iter().zip(&dims.arms) {
            for (d, label) in a.labels.iter().enumerate() {
                let i = a.range.start + d;
                let act = (rows.action_names.len() == rows.state_names.len()).then_some(i);
                out.push((
                    layout::state_action(dims.space, &arm.name, label),
                    Some(i),
                    act,
                ));
            }
        }
        return out;
    }
    let mut out: Vec<Pair> = rows
        .state_names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let a = rows.action_names.iter().position(|x| x == n);
            (format!("pose/{n}"), Some(i), a)
        })
        .collect();
    for (i, n) in rows.action_names.iter().enumerate() {
        if !rows.state_names.contains(n) {
            out.push((format!("pose/{n}"), None, Some(i)));
        }
    }
    out
}

/// One arm of the rig as the frames store it.
struct ArmRows {
    /// Its model (None when its URDF cannot be read).
    model: Option<ArmModel>,
    /// Where its joints sit in `rows.joint_names` (None when some are not stored).
    joints: Option<Vec<usize>>,
    /// Where its gripper's joints sit, when it has a gripper and they are stored.
    gripper: Option<Vec<usize>>,
}

fn positions(names: &[String], rows: &Rows) -> Option<Vec<usize>> {
    names
        .iter()
        .map(|n| rows.joint_names.iter().position(|x| x == n))
        .collect()
}

/// Per arm of `rig`, in rig order.
fn arm_rows(rig: &Rig, rows: &Rows) -> Vec<ArmRows> {
    rig.arms
        .iter()
        .map(|arm| ArmRows {
            model: ArmModel::new(arm)
                .map_err(|e| tracing::warn!("no 3-D view of arm '{}': {e}", arm.name))
                .ok(),
            joints: positions(&arm.joint_names, rows),
            gripper: arm
                .gripper
                .as_ref()
                .and_then(|g| positions(&g.joint_names, rows)),
        })
        .collect()
}

/// Logs the frames of an episode: `at(t)` sets the stream's time to frame `t`. `chunk` actions
/// from each frame on are drawn as the action chunk.
pub(crate) fn log_rows(
    rec: &RecordingStream,
    rows: &Rows,
    rig: Option<&Rig>,
    chunk: usize,
    at: &dyn Fn(usize),
) -> Result<()> {
    let r = Error::rerun;
    let dims = rig.map(|rig| Dims::new(rig, rows.space));
    let pairs = pairs(rows, rig, dims.as_ref());
    let fits = |n: usize| dims.as_ref().is_some_and(|d| d.fits(n));
    for (entity, s, a) in &pairs {
        let names: Vec<&str> = [s.map(|_| "state"), a.map(|_| "action")]
            .into_iter()
            .flatten()
            .collect();
        rec.log_static(entity.as_str(), &SeriesLines::new().with_names(names))
            .map_err(r)?;
    }
    let arms = rig.map(|rig| arm_rows(rig, rows)).unwrap_or_default();
    if let Some(rig) = rig {
        rec.log_static(layout::WORLD, &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())
            .map_err(r)?;
        for (i, a) in arms.iter().enumerate() {
            if let Some(m) = &a.model {
                m.log_static(rec, i, arms.len())?;
            }
            let name = &rig.arms[i].name;
            if rows.plot_joints && a.joints.is_some() {
                let names = rig.arms[i].joint_names.iter().map(String::as_str);
                rec.log_static(layout::joints(name), &SeriesLines::new().with_names(names))
                    .map_err(r)?;
                rec.log_static(
                    layout::gripper(name),
                    &SeriesLines::new().with_names(["opening (m)"]),
                )
                .map_err(r)?;
            }
            if let Some(d) = dims.as_ref().filter(|_| fits(rows.state_names.len())) {
                let strip = d.tcp_strip(&rows.state, i);
                rec.log_static(
                    layout::trajectory(name),
                    &LineStrips3D::new([strip]).with_radii([0.003]),
                )
                .map_err(r)?;
            }
        }
    }
    for t in 0..rows.state.len().max(rows.action.len()) {
        at(t);
        for (entity, s, a) in &pairs {
            let mut v = Vec::with_capacity(2);
            if let Some(i) = s {
                v.push(
                    rows.state
                        .get(t)
                        .and_then(|row| row.get(*i))
                        .map_or(f64::NAN, |x| f64::from(*x)),
                );
            }
            if let Some(i) = a {
                v.push(
                    rows.action
                        .get(t)
                        .and_then(|row| row.get(*i))
                        .map_or(f64::NAN, |x| f64::from(*x)),
                );
            }
            rec.log(entity.as_str(), &Scalars::new(v)).map_err(r)?;
        }
        let Some(rig) = rig else { continue };
        for (i, a) in arms.iter().enumerate() {
            let row = rows.joints.get(t);
            let pick = |idx: &[usize], row: &[f32]| -> Vec<f64> {
                idx.iter().map(|&j| f64::from(row[j])).collect()
            };
            if let (Some(idx), Some(row)) = (&a.joints, row) {
                let q = pick(idx, row);
                if rows.plot_joints {
                    rec.log(layout::joints(&rig.arms[i].name), &Scalars::new(q.clone()))
                        .map_err(r)?;
                }
                if let Some(model) = &a.model {
                    if let Err(e) = model.log_pose(rec, &q) {
                        tracing::debug!("frame {t}: {e}");
                    }
                }
            }
            if let (Some(idx), Some(row), Some(g), true) =
                (&a.gripper, row, &rig.arms[i].gripper, rows.plot_joints)
            {
                let width = g.model.width_m(&pick(idx, row));
                rec.log(layout::gripper(&rig.arms[i].name), &Scalars::new([width]))
                    .map_err(r)?;
            }
            let action_dims = dims.as_ref().filter(|_| fits(rows.action_names.len()));
            if let (Some(d), true) = (action_dims, chunk > 0) {
                let end = (t + chunk).min(rows.action.len());
                let strip = d.tcp_strip(&rows.action[t.min(end)..end], i);
                rec.log(
                    layout::action_chunk(&rig.arms[i].name),
                    &LineStrips3D::new([strip])
                        .with_radii([0.004])
                        .with_colors([0xff8c00ffu32]),
                )
                .map_err(r)?;
            }
            if let (Some(Some(p)), Some(d)) = (rows.predicted.get(t), action_dims) {
                let dim = rows.action_names.len();
                let steps: Vec<Vec<f32>> = p.chunks(dim).map(<[f32]>::to_vec).collect();
                rec.log(
                    layout::predicted_chunk(&rig.arms[i].name),
                    &LineStrips3D::new([d.tcp_strip(&steps, i)])
                        .with_radii([0.004])
                        .with_colors([0x1e90ffffu32]),
                )
                .map_err(r)?;
            }
        }
    }
    Ok(())
}

/// Per-tick quality of a recording's alignment.
#[derive(Debug, Default, Clone)]
pub(crate) struct Quality {
    /// Spread of the chosen frames' capture stamps (s).
    pub skew_s: Vec<f64>,
    /// Ticks with a stale frame or a joint gap.
    pub invalid: Vec<bool>,
    /// (stamp of the sample before the gap (ns), length (s), topic, samples missing).
    pub gaps: Vec<(u64, f64, String, u64)>,
}

/// Most gap lines written to the text log per episode (all are plotted).
const MAX_GAP_LINES: usize = 50;

/// Logs skew per tick, a marker per invalid tick and per gap, and one text line per gap.
pub(crate) fn log_quality(rec: &RecordingStream, q: &Quality, at: &dyn Fn(usize)) -> Result<()> {
    let r = Error::rerun;
    rec.log_static(
        layout::CAMERA_SKEW,
        &SeriesLines::new().with_names(["camera skew (ms)"]),
    )
    .map_err(r)?;
    rec.log_static(
        layout::INVALID_TICKS,
        &SeriesPoints::new()
            .with_names(["invalid tick"])
            .with_markers([rerun::components::MarkerShape::Cross]),
    )
    .map_err(r)?;
    rec.log_static(
        layout::GAPS,
        &SeriesPoints::new()
            .with_names(["gap (s)"])
            .with_markers([rerun::components::MarkerShape::Diamond]),
    )
    .map_err(r)?;
    for (t, skew) in q.skew_s.iter().enumerate() {
        at(t);
        rec.log(layout::CAMERA_SKEW, &Scalars::new([skew * 1e3]))
            .map_err(r)?;
        if q.invalid.get(t).copied().unwrap_or(false) {
            rec.log(layout::INVALID_TICKS, &Scalars::new([1.0]))
                .map_err(r)?;
        }
    }
    rec.disable_timeline(layout::TICK);
    for (k, (stamp, len_s, topic, missing)) in q.gaps.iter().enumerate() {
        rec.set_timestamp_nanos_since_epoch(layout::CAPTURE_TIME, *stamp as i64);
        rec.log(layout::GAPS, &Scalars::new([*len_s])).map_err(r)?;
        if k < MAX_GAP_LINES {
            let line = format!("gap of {len_s:.3} s on {topic} (about {missing} missing)");
            rec.log(
                layout::LOG,
                &TextLog::new(line).with_level(rerun::TextLogLevel::WARN),
            )
            .map_err(r)?;
        }
    }
    Ok(())
}

/// A prediction's chunks (`values`, one chunk per frame of `frames`) on the episode's rows (by
/// `frame_index`); an error when their size does not fit the dataset's action dimensions.
pub(crate) fn predicted_rows(
    frames: &[i64],
    values: &[f32],
    frame_index: &[i64],
    dim: usize,
) -> std::result::Result<Vec<Option<Vec<f32>>>, String> {
    let n = frames.len();
    if n == 0 || dim == 0 || values.len() % (n * dim) != 0 {
        return Err(format!(
            "the predicted chunks ({} values for {n} frames) do not fit {dim} action dimensions",
            values.len()
        ));
    }
    let per = values.len() / n;
    let at: BTreeMap<i64, usize> = frames.iter().enumerate().map(|(i, &f)| (f, i)).collect();
    Ok(frame_index
        .iter()
        .map(|f| at.get(f).map(|&i| values[i * per..(i + 1) * per].to_vec()))
        .collect())
}

/// A policy's predicted action chunks over one dataset episode (what `scaledp_policy`'s
/// `predict_episode` gives), drawn beside the recorded chunk.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Prediction {
    /// The frame (`frame_index`) each chunk was predicted at.
    pub frames: Vec<i64>,
    /// `[frames, C, A]` in the dataset's raw units, A = the dataset's action dimensions.
    pub values: Vec<f32>,
}
