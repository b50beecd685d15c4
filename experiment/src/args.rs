//! The command line of `scaledp experiment`.

use std::path::PathBuf;

use clap::{Args, Subcommand};

/// `scaledp experiment <command>`.
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Trains and evaluates the comparison's arms (ScaleDP-Ti non-causal vs causal, Ti vs S)
    /// with one recipe on the same demonstrations and seeds; each arm resumes where it stopped
    /// and writes its result as it lands, and the table and plot are rebuilt from what is there.
    Compare(CompareArgs),
    /// Rebuilds the table and the plot of an experiment from its arms' result files.
    Report(ReportArgs),
}

/// `scaledp experiment compare`.
#[derive(Debug, Clone, Args)]
pub struct CompareArgs {
    /// The training dataset (LeRobot v3.0, e.g. `scaledp convert` of `scaledp collect`).
    #[arg(long)]
    pub dataset: String,
    /// The experiment's name: results go to RESULTS/NAME, runs to RUNS/NAME.
    #[arg(long, default_value = "cpu-sim")]
    pub name: String,
    /// Arms to run, comma-separated (ti, ti-causal, s), one after the other.
    #[arg(long, value_delimiter = ',', default_value = "ti,ti-causal,s")]
    pub arms: Vec<String>,
    /// The training recipe every arm uses.
    #[arg(long, default_value = "cpu-sim")]
    pub preset: String,
    /// Optimizer steps instead of the preset's.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Checkpoint interval instead of the preset's (every checkpoint is evaluated on the
    /// validation seeds).
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// Samples per step instead of the preset's.
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Where the training runs live (checkpoints: never committed).
    #[arg(long, default_value = "runs/experiments")]
    pub runs: PathBuf,
    /// Where the results go (small files, meant to be committed).
    #[arg(long, default_value = "docs/results")]
    pub results: PathBuf,
    /// Validation episodes per checkpoint (seeds 1 000 000 …): they choose the checkpoint.
    #[arg(long, default_value_t = 20)]
    pub val_episodes: u64,
    /// Test episodes of the chosen checkpoint (seeds 2 000 000 …): the reported figure.
    #[arg(long, default_value_t = 50)]
    pub test_episodes: u64,
    /// Episodes of the chosen checkpoint in real time over loopback Zenoh (`eval --live`), for
    /// the recipe's arm (0: none).
    #[arg(long, default_value_t = 20)]
    pub live_episodes: u64,
    /// Skip the controls (untrained weights, frozen cameras, the scripted expert) of the
    /// recipe's arm.
    #[arg(long)]
    pub no_controls: bool,
    /// Longest evaluation episode (simulated s).
    #[arg(long, default_value_t = 30.0)]
    pub max_seconds: f64,
    /// Actions executed per predicted chunk.
    #[arg(long, default_value_t = 8)]
    pub action_steps: usize,
}

/// `scaledp experiment report`.
#[derive(Debug, Clone, Args)]
pub struct ReportArgs {
    /// The experiment's name.
    #[arg(long, default_value = "cpu-sim")]
    pub name: String,
    /// Where the results are.
    #[arg(long, default_value = "docs/results")]
    pub results: PathBuf,
}
