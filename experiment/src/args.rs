//! The command line of `scaledp experiment`.

use std::path::PathBuf;

use clap::{Args, Subcommand};

/// `scaledp experiment <command>`.
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Trains and evaluates the comparison's arms (ScaleDP-Ti non-causal vs causal, Ti vs S,
    /// DP-T) with one recipe on the same demonstrations and seeds, on one dataset or a
    /// benchmark's tasks; each arm resumes where it stopped and writes its result as it lands,
    /// and the table and plot are rebuilt from what is there.
    Compare(Box<CompareArgs>),
    /// Rebuilds the table and the plot of an experiment from its arms' result files.
    Report(ReportArgs),
    /// Trains DP-T and ScaleDP at the same depths on the same data and seeds for a few hundred
    /// steps and measures the spread of the blocks' gradient norms (the paper's explanation of
    /// why DP-T does not scale with depth) into docs/results/grad-scale/.
    GradScale(crate::GradScaleArgs),
}

/// A simulation benchmark `compare` can run end to end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Benchmark {
    /// MetaWorld: per task, demonstrations by its scripted expert (`scaledp collect --rig
    /// metaworld/<task> --successes N`), converted, every arm trained and scored on the test
    /// seeds, the controls beside them; the table by difficulty level.
    Metaworld,
    /// ALOHA's bimanual tasks (transfer-cube, insertion): per task, 50 demonstrations by the
    /// ACT paper's scripted experts, converted with joint-space actions (what ALOHA's leader
    /// arms command), every arm trained and scored on the test seeds, the controls beside them.
    Aloha,
}

/// `scaledp experiment compare`.
#[derive(Debug, Clone, Args)]
pub struct CompareArgs {
    /// The training dataset (LeRobot v3.0, e.g. `scaledp convert` of `scaledp collect`); not
    /// with --benchmark, which makes its own.
    #[arg(long, required_unless_present = "benchmark")]
    pub dataset: Option<String>,
    /// Run a simulation benchmark's tasks instead of one dataset (--tasks).
    #[arg(long, value_enum, conflicts_with = "dataset")]
    pub benchmark: Option<Benchmark>,
    /// The benchmark's tasks, comma-separated (MetaWorld task names; ALOHA's transfer-cube,
    /// insertion), each run to the end (every arm) before the next.
    #[arg(long, value_delimiter = ',', requires = "benchmark")]
    pub tasks: Vec<String>,
    /// Successful demonstrations per task [MetaWorld: 20, as the paper; ALOHA: 50, as the ACT
    /// paper].
    #[arg(long)]
    pub demos: Option<u64>,
    /// Episodes of each control of a benchmark task (untrained weights and frozen cameras of
    /// the first arm; the scripted expert always runs on every test seed).
    #[arg(long, default_value_t = 20)]
    pub controls_episodes: u64,
    /// The experiment's name: results go to RESULTS/NAME, runs to RUNS/NAME (default: cpu-sim,
    /// or the benchmark's name).
    #[arg(long)]
    pub name: Option<String>,
    /// Arms to run, comma-separated (ti, ti-causal, s, ti-sincos, ti-learned-sincos, ti-x3,
    /// ti-causal-x3, dp-t, dp-t-l12, dp-t-l14),
    /// one after the other [ti,ti-causal,s; a benchmark: ti,dp-t].
    #[arg(long, value_delimiter = ',')]
    pub arms: Vec<String>,
    /// The training recipe every arm uses [cpu-sim; MetaWorld: cpu-metaworld; ALOHA:
    /// cpu-aloha].
    #[arg(long)]
    pub preset: Option<String>,
    /// Training seed (weights, data order, crops, diffusion noise) instead of 0: a replicate of
    /// each arm beside the seed-0 runs (benchmarks only), as `<task>--<arm>--seed<N>.json` and
    /// run directory `<arm>-seed<N>`; the table shows every seed and pairs arms by seed.
    #[arg(long, default_value_t = 0)]
    pub train_seed: u64,
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
    /// Validation episodes per checkpoint (seeds 1 000 000 …): they choose the checkpoint
    /// (0: the last checkpoint is scored, as the benchmarks do).
    #[arg(long)]
    pub val_episodes: Option<u64>,
    /// Test episodes of the chosen checkpoint (seeds 3 000 000 …): the reported figure.
    #[arg(long, default_value_t = 50)]
    pub test_episodes: u64,
    /// Episodes of the chosen checkpoint in real time over loopback Zenoh (`eval --live`), for
    /// the recipe's arm (0: none) [20; a benchmark: 0].
    #[arg(long)]
    pub live_episodes: Option<u64>,
    /// Skip the controls (untrained weights, frozen cameras, the scripted expert) of the
    /// recipe's arm.
    #[arg(long)]
    pub no_controls: bool,
    /// Train nothing: score the tasks' finished (task, arm) results and their controls again
    /// with this build (the same checkpoints, seeds and settings), after a change to the
    /// simulator's bridge; each file keeps its earlier figures in `earlier_scores`. The table
    /// marks results scored by an older bridge than the newest among them.
    #[arg(long, requires = "benchmark")]
    pub rescore: bool,
    /// Longest evaluation episode (simulated s).
    #[arg(long, default_value_t = 30.0)]
    pub max_seconds: f64,
    /// Actions executed per predicted chunk [half the recipe's chunk: 8 of 16, ALOHA 16 of 32].
    #[arg(long)]
    pub action_steps: Option<usize>,
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
    /// Also rewrite the results summary of this README (between `<!-- results-summary -->` and
    /// `<!-- /results-summary -->`) from the files of every benchmark under `--results`.
    #[arg(long)]
    pub readme: Option<PathBuf>,
}
