//! Does a checkpoint fit a rig? Checked before anything moves, each mismatch one line naming
//! the checkpoint's side and the rig's.

use scaledp_policy::CheckpointConfig;
use scaledp_schema::rig::Rig;

use crate::error::{Error, Result};

/// The camera of `rig` a checkpoint key (`observation.images.<name>`) refers to.
pub fn camera_index(rig: &Rig, key: &str) -> Option<usize> {
    let name = key.strip_prefix("observation.images.").unwrap_or(key);
    rig.cameras.iter().position(|c| c.name == name)
}

/// The rig a checkpoint was trained on: its config's `rig` holds the dataset's rig, as the
/// rig's TOML (what `scaledp convert` stores) or as a name.
pub fn trained_rig(cfg: &CheckpointConfig) -> Option<std::result::Result<Rig, String>> {
    let text = cfg.rig.as_deref()?.trim();
    if text.is_empty() {
        return None;
    }
    if text.contains('\n') || text.contains('=') {
        return Some(
            Rig::parse(text, std::path::Path::new("checkpoint config.json"))
                .map_err(|e| e.to_string()),
        );
    }
    Some(Err(text.to_string()))
}

/// The name of the rig a checkpoint was trained on, if it says.
pub fn trained_rig_name(cfg: &CheckpointConfig) -> Option<String> {
    trained_rig(cfg).map(|r| match r {
        Ok(rig) => rig.name,
        Err(name) => name,
    })
}

/// Checks that `cfg` (a checkpoint's config, `ckpt` its name for messages) can drive `rig`:
/// the rig it was trained for (when it names one), every camera it reads, its state and action
/// names (the converter's, in the checkpoint's action space), and a command topic on every arm
/// (a `PoseStamped` or a leader's `JointState`: [`crate::controller`] converts between the two). Returns the rig camera index of each checkpoint camera.
pub fn check(cfg: &CheckpointConfig, ckpt: &str, rig: &Rig) -> Result<Vec<usize>> {
    let bad = |m: String| Err(Error::Incompatible(m));
    if let Some(trained) = trained_rig_name(cfg) {
        if trained != rig.name {
            return bad(format!(
                "checkpoint {ckpt} was trained on rig {trained}, not {}: its cameras, arms and \
                 frames belong to that rig (pass --rig {trained})",
                rig.name
            ));
        }
    }
    let trained = match trained_rig(cfg) {
        Some(Ok(r)) => Some(r),
        _ => None,
    };
    let have: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
    let mut cams = Vec::new();
    for key in &cfg.model.cameras {
        match camera_index(rig, key) {
            Some(i) => {
                let now = &rig.cameras[i];
                let then = trained
                    .as_ref()
                    .and_then(|t| t.cameras.iter().find(|c| c.name == now.name));
                if let Some(then) = then.filter(|t| t.vertical_fov_deg != now.vertical_fov_deg) {
                    let fov = |f: Option<f64>| match f {
                        Some(d) => format!("{d}°"),
                        None => "the simulator's own".to_string(),
                    };
                    return bad(format!(
                        "checkpoint {ckpt} learned camera {} at a vertical field of view of {}; \
                         rig {} renders it at {}: not the pictures it was trained on",
                        now.name,
                        fov(then.vertical_fov_deg),
                        rig.name,
                        fov(now.vertical_fov_deg)
                    ));
                }
                cams.push(i)
            }
            None => {
                return bad(format!(
                    "checkpoint {ckpt} reads camera {key}, which rig {} lacks (it has {have:?})",
                    rig.name
                ))
            }
        }
    }
    let names = scaledp_converter::state_names(rig, cfg.action_space);
    for (what, dim, got) in [
        ("state", cfg.model.state_dim, &cfg.state_names),
        ("action", cfg.model.action_dim, &cfg.action_names),
    ] {
        if dim != names.len() || (!got.is_empty() && got != &names) {
            return bad(format!(
                "checkpoint {ckpt} has a {dim}-D {what} {got:?}; rig {} with {} arm(s) needs \
                 {} {names:?}",
                rig.name,
                rig.arms.len(),
                names.len()
            ));
        }
    }
    for arm in &rig.arms {
        if arm.command_topic.is_none() {
            return bad(format!(
                "rig {}: arm '{}' has no command_topic: nothing to send its targets to",
                rig.name, arm.name
            ));
        }
    }
    if !(cfg.fps.is_finite() && cfg.fps > 0.0) {
        return bad(format!("checkpoint {ckpt}: control rate (fps) {}", cfg.fps));
    }
    if (cfg.fps - rig.control_rate_hz).abs() > 1e-6 {
        tracing::warn!(
            "checkpoint {ckpt} was trained at {} Hz, rig {} says {} Hz: acting at {} Hz",
            cfg.fps,
            rig.name,
            rig.control_rate_hz,
            cfg.fps
        );
    }
    Ok(cams)
}
