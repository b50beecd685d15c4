//! `scaledp view`.

use std::path::PathBuf;

use clap::Args;

use super::common::parse_action_space;

/// `scaledp view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Recordings (.mcap, also a .partial one), ROS 1 .bag files, rosbag2 directories or .db3
    /// files, directories of them, or LeRobot v3.0 datasets (a directory or s3://bucket/prefix).
    #[arg(required = true, value_name = "PATH")]
    pub paths: Vec<String>,
    /// Only this episode: a dataset's episode_index, or the N-th input of a directory
    /// (repeatable; default: every episode).
    #[arg(long, value_name = "N")]
    pub episode: Vec<u64>,
    /// Write an .rrd file instead of showing a viewer.
    #[arg(long, value_name = "OUT.rrd", conflicts_with = "connect")]
    pub save: Option<PathBuf>,
    /// Stream to a rerun viewer already running, e.g. rerun+http://host:9876/proxy.
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Downsample images wider than this (pixels).
    #[arg(long, value_name = "PX")]
    pub max_width: Option<u32>,
    /// Rig file or shipped rig name mapping topics (default: the rig stored in the input, else
    /// detected).
    #[arg(long)]
    pub rig: Option<String>,
    /// Actions drawn ahead of each frame as the action chunk.
    #[arg(long, default_value_t = 16)]
    pub chunk: usize,
    /// Show recordings' state and action in this space (tcp or joints), as `scaledp convert
    /// --action` would convert them; a dataset is shown in its own.
    #[arg(long = "action", default_value = "tcp", value_parser = parse_action_space)]
    pub action_space: scaledp_schema::ActionSpace,
    /// A policy checkpoint whose predicted chunks are drawn beside the dataset's (one dataset,
    /// with --episode).
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
}
