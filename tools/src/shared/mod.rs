//! What several commands share, so each command module depends only on the libraries and
//! this one: the device, rig and controller flags, Zenoh and interrupt plumbing, the recording
//! session's tally and timer, scoring, input locations (paths or `s3://` URLs), and the rerun
//! viewer glue.

pub mod attend;
mod control;
mod scoring;
mod session;
pub mod viewer;

use anyhow::{bail, Context, Result};

use crate::cli::{CompressionArg, NetArgs};
pub use control::{rig_for, ControlArgs};
pub use scoring::{wilson_interval, Successes};
pub use session::{timed_episodes, wait_for_topics};

/// A command-line path or `s3://` URL (convert, merge and recover take either).
pub fn location(arg: &std::path::Path) -> Result<scaledp_converter::Location> {
    Ok(scaledp_converter::Location::parse(arg.as_os_str())?)
}

/// The device named on the command line.
pub fn device(name: &str) -> Result<candle_core::Device> {
    match name {
        "cpu" => Ok(candle_core::Device::Cpu),
        "cuda" => candle_core::Device::new_cuda(0)
            .context("--device cuda needs a build with `--features scaledp-policy/cuda` and a GPU"),
        other => bail!("--device {other}: cpu or cuda"),
    }
}

/// The Zenoh config of the network flags; `default_listen` when none is given.
pub fn zenoh_config(net: &NetArgs, default_listen: &[String]) -> Result<zenoh::Config> {
    let listen = if net.listen.is_empty() && net.connect.is_empty() && net.zenoh_config.is_none() {
        default_listen
    } else {
        &net.listen
    };
    Ok(scaledp_recorder::net::zenoh_config(
        net.zenoh_config.as_deref(),
        &net.connect,
        listen,
    )?)
}

/// The recorder's compression of the CLI choice.
pub fn compression(c: CompressionArg) -> scaledp_recorder::Compression {
    match c {
        CompressionArg::None => scaledp_recorder::Compression::None,
        CompressionArg::Lz4 => scaledp_recorder::Compression::Lz4,
        CompressionArg::Zstd => scaledp_recorder::Compression::Zstd,
    }
}

/// A flag set by Ctrl-C (SIGINT) or SIGTERM.
pub fn interrupt_flag() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Arc, OnceLock};
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let f = flag.clone();
        if let Err(e) = ctrlc::set_handler(move || f.store(true, Ordering::Relaxed)) {
            tracing::warn!("cannot catch Ctrl-C: {e}");
        }
        flag
    })
    .clone()
}

/// A loopback TCP port nothing listens on right now.
pub fn free_port() -> Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

/// The collection manifests (`collect.jsonl` of `scaledp collect`) beside the recordings a
/// local dataset was converted from, as its `meta/info.json` lists them (`scaledp.sources`):
/// the seeds a policy trained on it has seen. Empty for datasets elsewhere or without sources.
pub fn training_manifests(dataset: &str) -> Vec<std::path::PathBuf> {
    let info = std::path::Path::new(dataset).join("meta/info.json");
    let Ok(bytes) = std::fs::read(&info) else {
        return Vec::new();
    };
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
        return Vec::new();
    };
    let mut dirs: Vec<std::path::PathBuf> = v["scaledp"]["sources"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|s| s["source"].as_str())
        .filter_map(|s| {
            std::path::Path::new(s)
                .parent()
                .map(|p| p.join("collect.jsonl"))
        })
        .filter(|p| p.exists())
        .collect();
    dirs.sort();
    dirs.dedup();
    dirs
}
