//! The controls of a task, scored on the test seeds: the scripted expert, the untrained
//! weights and the cameras frozen.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use scaledp_deploy::Split;
use scaledp_schema::Rig;

use crate::audit;
use crate::evaluate::{self, EvalPlan, Kind};
use crate::figures::{Controls, EvalFigures};

/// The controls of a task on the test seeds: the scripted expert (`expert` episodes), the
/// untrained weights of `arm`'s run and its last checkpoint with its cameras frozen (`n`
/// each), and the simulator that scored them; none until the run has its step-0 and a later
/// checkpoint.
pub(super) fn score_controls(
    rig: &Rig,
    task_dir: &Path,
    arm: &str,
    expert: u64,
    n: u64,
    plan: &EvalPlan,
) -> Result<Option<(Controls, BTreeMap<String, String>)>> {
    let ckpts = evaluate::checkpoints(&task_dir.join(arm))?;
    let (Some((0, untrained)), Some((_, last))) = (ckpts.first(), ckpts.last()) else {
        return Ok(None);
    };
    let expert = evaluate::expert(task_dir, rig, Split::Test, expert, plan)?;
    let untrained = evaluate::checkpoint(untrained, Some(rig), Kind::Policy, Split::Test, n, plan)?;
    let frozen = evaluate::checkpoint(last, Some(rig), Kind::Frozen, Split::Test, n, plan)?;
    let simulator = audit::simulator(&frozen);
    Ok(Some((
        Controls {
            untrained: Some(EvalFigures::of(&untrained)),
            frozen_cameras: Some(EvalFigures::of(&frozen)),
            scripted_expert: Some(EvalFigures::of(&expert)),
        },
        simulator,
    )))
}
