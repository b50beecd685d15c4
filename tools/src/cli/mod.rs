//! Every flag of `scaledp`: the command tree here, each command's flags in its own module.

use clap::{Parser, Subcommand};

mod common;
mod convert;
mod record;
mod sim;
mod view;

pub use common::{CameraCodecArg, CompressionArg, KeysArg, NetArgs, OperatorArg};
pub use convert::*;
pub use record::*;
pub use sim::*;
pub use view::*;

/// How a command ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitStatus {
    /// 0: everything worked.
    Success,
    /// 1: the command failed.
    Error,
    /// 3: the command finished, but some data was lost (drops, failed episodes).
    DataLost,
}

impl From<scaledp_bench::Outcome> for ExitStatus {
    fn from(o: scaledp_bench::Outcome) -> Self {
        match o {
            scaledp_bench::Outcome::Completed => ExitStatus::Success,
            scaledp_bench::Outcome::DataLost => ExitStatus::DataLost,
        }
    }
}

impl From<ExitStatus> for std::process::ExitCode {
    fn from(s: ExitStatus) -> Self {
        Self::from(match s {
            ExitStatus::Success => 0,
            ExitStatus::Error => 1,
            ExitStatus::DataLost => 3,
        })
    }
}

/// scaledp: record teleoperated demonstrations and turn them into training data for ScaleDP.
#[derive(Debug, Parser)]
#[command(name = "scaledp", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
    /// More log output (-v debug, -vv trace); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only warnings and errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a simulated rig that publishes cameras and joint states over Zenoh like a real one
    /// and follows commands (a Cartesian TCP target and a gripper opening per arm).
    Sim(SimArgs),
    /// Collect demonstrations in one process: the simulated task, its scripted teleoperator and
    /// the recorder, one episode per seed, each labelled by the task's scorer.
    Collect(CollectArgs),
    /// Record teleop episodes from Zenoh into one MCAP file each.
    Record(RecordArgs),
    /// Repair an MCAP file cut short by a crash, keeping every complete chunk.
    Recover(RecoverArgs),
    /// Convert recordings and ROS bags into a LeRobot v3.0 dataset.
    Convert(ConvertArgs),
    /// Work with converted datasets.
    #[command(subcommand)]
    Dataset(DatasetCommand),
    /// Measure throughput and cost.
    #[command(subcommand)]
    Bench(scaledp_bench::BenchCommand),
    /// Train a ScaleDP policy on a LeRobot dataset (checkpoints, metrics.jsonl, --resume).
    Train(Box<crate::commands::train::TrainArgs>),
    /// Run a checkpoint over a recorded episode: predicted vs recorded actions and their error.
    Predict(crate::commands::predict::PredictArgs),
    /// Drive a rig with a checkpoint over Zenoh: observations built as the converter built the
    /// training data, clamped Cartesian commands at the control rate (--dry-run prints them).
    Serve(crate::commands::serve::ServeArgs),
    /// A checkpoint's success rate on seeded, held-out episodes of the simulated task (95 %
    /// Wilson interval, per-episode outcomes, a JSON report).
    Eval(crate::commands::eval::EvalArgs),
    /// The paper's comparisons at this machine's scale (non-causal vs causal attention, Ti vs S)
    /// with one recipe, chosen on validation seeds, reported on test seeds with controls.
    #[command(subcommand)]
    Experiment(scaledp_experiment::ExperimentCommand),
    /// The whole path on a simulated rig: records a few short episodes over loopback, converts
    /// them into a LeRobot dataset and runs one epoch of the training-data loader.
    Demo(DemoArgs),
    /// Show recordings, bags and LeRobot datasets in the rerun viewer (or write an .rrd file).
    View(ViewArgs),
}
