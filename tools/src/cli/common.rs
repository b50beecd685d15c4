//! Flags several commands share: the Zenoh session, the simulated cameras' codec, key layout and
//! operator.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

/// Where the Zenoh session connects and listens.
#[derive(Debug, Clone, Args)]
pub struct NetArgs {
    /// A standard Zenoh config file (json5): mode, endpoints, TLS, scouting…
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// Endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable; overrides the file).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Endpoint to listen on (repeatable; overrides the file).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
}

/// The codec of simulated cameras (`sim --camera-codec`, `collect --camera-codec`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CameraCodecArg {
    /// Each camera as `foxglove_msgs/msg/CompressedVideo`: H.264 Annex B, no B-frames, an IDR
    /// with SPS/PPS once a second.
    H264,
}

impl CameraCodecArg {
    /// Makes every camera of `rig` publish (and be recorded) as this codec.
    pub fn apply(self, rig: &mut scaledp_schema::Rig) {
        for c in &mut rig.cameras {
            c.encoding = Some("h264".into());
            c.compressed = false;
        }
    }
}

/// Key layout of the simulated publishers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KeysArg {
    /// zenoh-bridge-ros2dds: the topic without its leading '/'.
    Bridge,
    /// rmw_zenoh: <domain>/<topic>/<type>/<hash>, with attachments.
    Rmw,
}

/// Who drives the simulated arms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OperatorArg {
    /// Nobody in-process: the arms hold still until commands arrive over Zenoh.
    None,
    /// The scripted expert, as a teleoperator publishing leader commands.
    Scripted,
}

pub(super) fn parse_action_space(s: &str) -> Result<scaledp_schema::ActionSpace, String> {
    s.parse()
}

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CompressionArg {
    /// No compression.
    None,
    /// LZ4 (fast).
    Lz4,
    /// Zstandard level 1 (smaller).
    Zstd,
}
