//! Does a checkpoint fit a rig? Checked before anything moves, each mismatch one line naming
//! the checkpoint's side and the rig's.

use scaledp_policy::CheckpointConfig;
use scaledp_schema::fov_label;
use scaledp_schema::rig::Rig;

use crate::error::{Error, Result};

/// The camera of `rig` a checkpoint key (`observation.images.<name>`) refers to.
pub fn camera_index(rig: &Rig, key: &str) -> Option<usize> {
    let name = key.strip_prefix("observation.images.").unwrap_or(key);
    rig.cameras.iter().position(|c| c.name == name)
}

/// The rig a checkpoint's config stores (the dataset's): its TOML, as `scaledp convert` stores
/// it, or a name.
enum Stored<'a> {
    Toml(&'a str),
    Name(&'a str),
}

fn stored(cfg: &CheckpointConfig) -> Option<Stored<'_>> {
    let text = cfg.rig.as_deref()?.trim();
    if text.is_empty() {
        None
    } else if text.contains('\n') || text.contains('=') {
        Some(Stored::Toml(text))
    } else {
        Some(Stored::Name(text))
    }
}

/// The rig a checkpoint was trained on: the TOML its config stores, or the shipped rig its
/// config names; `None` when it names none. A stored rig that does not load is one line naming
/// the checkpoint.
pub fn trained_rig(cfg: &CheckpointConfig, ckpt: &str) -> Result<Option<Rig>> {
    let bad = |e: scaledp_schema::Error| {
        Error::Incompatible(format!(
            "checkpoint {ckpt}: the rig it was trained on does not load: {e}"
        ))
    };
    match stored(cfg) {
        None => Ok(None),
        Some(Stored::Toml(t)) => {
            Rig::parse(t, std::path::Path::new(&format!("{ckpt}/config.json")))
                .map(Some)
                .map_err(bad)
        }
        Some(Stored::Name(n)) => Rig::load_or_builtin(n).map(Some).map_err(bad),
    }
}

/// The name of the rig a checkpoint was trained on, if it says (read leniently: a stored rig
/// with fields this build does not know still has a name).
pub fn trained_rig_name(cfg: &CheckpointConfig) -> Option<String> {
    match stored(cfg)? {
        Stored::Name(n) => Some(n.to_string()),
        Stored::Toml(t) => toml::from_str::<toml::Value>(t)
            .ok()?
            .get("name")?
            .as_str()
            .map(str::to_string),
    }
}

/// Checks that `cfg` (a checkpoint's config, `ckpt` its name for messages) can drive `rig`:
/// the rig it was trained for (when it names one), every camera it reads, its state and action
/// names (the converter's, in the checkpoint's action space), and a command topic on every arm
/// (a `PoseStamped` or a leader's `JointState`: [`crate::controller`] converts between the two),
/// and each camera's field of view against the pictures it learned from. Returns the rig camera
/// index of each checkpoint camera.
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
    // The pictures it learned from: a stored rig's cameras at their fields of view.
    let trained = match stored(cfg) {
        Some(Stored::Toml(_)) => trained_rig(cfg, ckpt)?,
        _ => None,
    };
    let have: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
    let mut cams = Vec::new();
    for key in &cfg.model.cameras {
        match camera_index(rig, key) {
            Some(i) => cams.push(i),
            None => {
                return bad(format!(
                    "checkpoint {ckpt} reads camera {key}, which rig {} lacks (it has {have:?})",
                    rig.name
                ))
            }
        }
    }
    for now in cams.iter().map(|&i| &rig.cameras[i]) {
        let then = trained
            .as_ref()
            .and_then(|t| t.cameras.iter().find(|c| c.name == now.name));
        if let Some(then) = then.filter(|t| t.vertical_fov_deg != now.vertical_fov_deg) {
            return bad(format!(
                "checkpoint {ckpt} learned camera {} at a vertical field of view of {}; rig {} \
                 renders it at {} (eval without --rig runs the checkpoint's own rig)",
                now.name,
                fov_label(then.vertical_fov_deg),
                rig.name,
                fov_label(now.vertical_fov_deg)
            ));
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
