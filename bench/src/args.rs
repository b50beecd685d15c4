//! The flags of `scaledp bench`, one struct per benchmark.

use std::path::PathBuf;

use clap::{Args, Subcommand, ValueEnum};

/// `scaledp bench`.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Soak the recorder: the reference load (2 ZED 1080p with depth, 3 RealSense with depth and
    /// camera_info, 2 arms at 500 Hz, /tf) over loopback into a recorder process, episodes back
    /// to back for --minutes; messages lost per topic, resident memory, CPU, MB/s written.
    Record(BenchRecordArgs),
    /// Convert a fixed generated set of recordings and report frames/s, MB/s and peak memory,
    /// against the usual single-process Python route.
    Convert(BenchConvertArgs),
    /// Run the training-data loader over a generated bimanual dataset and report samples/s,
    /// images/s, MB/s and peak memory against pure JPEG decoding and LeRobot's DataLoader.
    Load(BenchLoadArgs),
    /// Train ScaleDP-Ti on a converted simulated dataset and report samples/s and the data-wait
    /// share, beside the same model in PyTorch; DDIM latency per action chunk for Ti and S.
    Train(BenchTrainArgs),
}

/// Chunk compression of the recorder under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Compression {
    /// No compression.
    None,
    /// LZ4 (fast).
    Lz4,
    /// Zstandard level 1 (smaller).
    Zstd,
}

impl Compression {
    /// The value of `scaledp record --compression`.
    pub fn flag(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Lz4 => "lz4",
            Compression::Zstd => "zstd",
        }
    }
}

/// `scaledp bench record`.
#[derive(Debug, Args)]
pub struct BenchRecordArgs {
    /// Minutes of load: episodes of --episode-seconds back to back (the last one shorter when
    /// they do not divide).
    #[arg(long, default_value_t = 60.0)]
    pub minutes: f64,
    /// Seconds of load per episode.
    #[arg(long, default_value_t = 60.0)]
    pub episode_seconds: f64,
    /// Fraction of the reference load's bytes offered: every image's pixel count times this
    /// (width and height by its square root), rates unchanged.
    #[arg(long, default_value_t = 1.0, value_parser = parse_fraction)]
    pub load: f64,
    /// Chunk compression of the recorder.
    #[arg(long, value_enum, default_value = "lz4")]
    pub compression: Compression,
    /// Where the episodes and the report go (default: target/bench-record in the workspace
    /// holding the current directory, else a directory in the system temp dir).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Keep the finished episodes (default: each is deleted once checked; an hour of the
    /// reference load does not fit on a disk).
    #[arg(long)]
    pub keep: bool,
    /// The JSON report (default: report.json in the output directory).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// End an episode early, and start no more, when the output disk has less free (GB).
    #[arg(long, default_value_t = 20.0)]
    pub min_free_gb: f64,
    /// Seconds between samples of the recorder's resident memory.
    #[arg(long, default_value_t = 10.0)]
    pub sample_seconds: f64,
    /// Internal: run the recorder in this process, driven over stdin, reporting on stdout;
    /// the benchmark measures it as a child process.
    #[arg(long, hide = true, requires = "endpoint")]
    pub worker: bool,
    /// Internal: the Zenoh endpoint a --worker connects to.
    #[arg(long, hide = true)]
    pub endpoint: Option<String>,
}

/// A fraction in (0, 1].
fn parse_fraction(s: &str) -> Result<f64, String> {
    let f: f64 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if f > 0.0 && f <= 1.0 {
        Ok(f)
    } else {
        Err(format!("{s}: need a fraction in (0, 1]"))
    }
}

/// `scaledp bench convert`.
#[derive(Debug, Args)]
pub struct BenchConvertArgs {
    /// Episodes generated and converted.
    #[arg(long, default_value_t = 4)]
    pub episodes: usize,
    /// Seconds per episode.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Rig file, or the name of a shipped rig.
    #[arg(long, default_value = "franka_2zed")]
    pub rig: String,
    /// Episodes converted at once (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Keep the generated recordings and the datasets here (default: a temporary directory,
    /// removed afterwards).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Skip the Python baseline.
    #[arg(long)]
    pub no_python: bool,
    /// Skip the S3 row (the recordings converted bucket to bucket on a loopback moto server
    /// from the tests' venv).
    #[arg(long)]
    pub no_s3: bool,
    /// The Python of the baseline, with rosbags, numpy, Pillow and pyarrow (default:
    /// $SCALEDP_PYTHON, else .venv/bin/python in the workspace holding the current directory,
    /// which `bash scripts/setup-python.sh` makes).
    #[arg(long, value_name = "PYTHON")]
    pub python: Option<PathBuf>,
    /// Also convert with the cameras as video features in these codecs (av1, h264), beside
    /// JPEG at qualities 50, 75 and 90, and print frames/s, size and PSNR against JPEG q100.
    #[arg(long, value_name = "CODEC", value_delimiter = ',', value_parser = ["av1", "h264"])]
    pub video: Vec<String>,
}

/// `scaledp bench load`.
#[derive(Debug, Args)]
pub struct BenchLoadArgs {
    /// Episodes of the generated dataset (bimanual_ur5_3rs, 3 cameras stored as 320×240 JPEG).
    #[arg(long, default_value_t = 100)]
    pub episodes: usize,
    /// Seconds per episode (frames at the rig's 10 Hz control rate).
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Samples per batch.
    #[arg(long, default_value_t = 64)]
    pub batch_size: usize,
    /// Decoding threads of the loader and of the pure-decode run, and LeRobot's DataLoader
    /// workers (default: the number of cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Cache directory for the generated datasets, reused when complete (default:
    /// target/bench-load in the workspace holding the current directory, else a directory in
    /// the system temp dir).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// The streaming run uses a dataset this many times larger (the generated one merged with
    /// itself under new episode indices); 0 skips the streaming run.
    #[arg(long, default_value_t = 4)]
    pub streaming_factor: usize,
    /// Episodes open at once in streaming mode.
    #[arg(long, default_value_t = 16)]
    pub streaming_buffer: usize,
    /// Batches LeRobot's DataLoader is timed over (after one warm-up batch).
    #[arg(long, default_value_t = 20)]
    pub lerobot_batches: usize,
    /// Skip the Python routes (LeRobot's DataLoader and our module `scaledp_data`).
    #[arg(long, alias = "no-lerobot")]
    pub no_python: bool,
    /// Also measure the same dataset with its cameras as video features of this codec
    /// (written from the JPEGs with LeRobot's encoder settings by PyAV on the benchmark Python,
    /// cached beside the JPEG dataset): our loader on it, LeRobot's DataLoader on it (pyav
    /// backend) and, with a streaming run, the larger dataset as video.
    #[arg(long, value_enum, default_value = "av1")]
    pub video: BenchVideo,
    /// The Python of both routes, with LeRobot and torch (default: $SCALEDP_BENCH_PYTHON, else
    /// .venv-bench/bin/python in the workspace holding the current directory, which
    /// `bash scripts/setup-bench-python.sh` makes). The scaledp_data wheel comes from
    /// $SCALEDP_WHEEL_DIR, else that workspace's target/wheels (`bash scripts/build-python.sh`).
    #[arg(long, value_name = "PYTHON")]
    pub python: Option<PathBuf>,
    /// Internal: run one loader epoch over DATASET in this process and print JSON; the
    /// benchmark measures it as a child process.
    #[arg(
        long,
        hide = true,
        value_enum,
        value_name = "MODE",
        requires = "dataset"
    )]
    pub worker: Option<WorkerMode>,
    /// Internal: the dataset of a --worker run.
    #[arg(long, hide = true)]
    pub dataset: Option<PathBuf>,
}

/// The codec of `bench load`'s video dataset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BenchVideo {
    /// libsvtav1, yuv420p, g=2, crf=30, preset 12 (LeRobot 0.4.4's defaults).
    Av1,
    /// libx264, yuv420p, g=2, crf 23.
    H264,
    /// No video routes.
    None,
}

impl BenchVideo {
    /// The codec name `make_video_dataset.py --codec` takes, None for no video.
    pub fn codec(self) -> Option<&'static str> {
        match self {
            BenchVideo::Av1 => Some("av1"),
            BenchVideo::H264 => Some("h264"),
            BenchVideo::None => None,
        }
    }
}

/// `scaledp bench train`.
#[derive(Debug, Args)]
pub struct BenchTrainArgs {
    /// Simulated episodes converted into the dataset.
    #[arg(long, default_value_t = 4)]
    pub episodes: usize,
    /// Seconds per episode.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Rig file, or the name of a shipped rig.
    #[arg(long, default_value = "franka_2zed")]
    pub rig: String,
    /// Images of WxH before the crop: the dataset is converted at that size, as the recipe's
    /// `scaledp convert --size` does (default: the converter's own size).
    #[arg(long, value_name = "WxH")]
    pub image_size: Option<String>,
    /// Train with a named recipe's settings (cpu-sim: ResNet width 32, two noise draws per
    /// observation, batch 64; pair it with `--image-size 64x64`, the recipe's images), the
    /// PyTorch route doing the same.
    #[arg(long)]
    pub preset: Option<String>,
    /// Samples per step (default 64, or the preset's).
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Models timed, comma-separated: ti (ScaleDP-Ti), dp-t (the paper's baseline).
    #[arg(long, value_delimiter = ',', default_value = "ti,dp-t")]
    pub models: Vec<String>,
    /// ScaleDP-Ti's attention over the action chunk, as `scaledp train --attention`: causal
    /// or non-causal (the paper's) [the preset's: causal, `paper`'s non-causal]. DP-T keeps
    /// its own masks.
    #[arg(long)]
    pub attention: Option<String>,
    /// Forward/backward at most this many samples at a time.
    #[arg(long)]
    pub micro_batch: Option<usize>,
    /// Timed steps (after the warm-up steps).
    #[arg(long, default_value_t = 3)]
    pub steps: usize,
    /// Untimed steps first, on each side: PyTorch's second and third steps still run 20–40 %
    /// slower than its later ones (its allocator and oneDNN's primitive cache filling).
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Rounds of the Rust-vs-PyTorch comparison, the two sides alternating (the figure is the
    /// median of the rounds' ratios).
    #[arg(long, default_value_t = 3)]
    pub rounds: usize,
    /// DDIM chunks timed per model size.
    #[arg(long, default_value_t = 20)]
    pub latency_runs: usize,
    /// Keep the recordings and the dataset here (default: a temporary directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Skip the PyTorch route.
    #[arg(long)]
    pub no_python: bool,
    /// The Python of the PyTorch route (default: $SCALEDP_BENCH_PYTHON, else .venv-bench/bin/python
    /// in the workspace holding the current directory, which `bash scripts/setup-bench-python.sh`
    /// makes).
    #[arg(long)]
    pub python: Option<PathBuf>,
}

/// How the loader epoch of a `bench load --worker` child reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WorkerMode {
    /// Random access: any sample of the dataset at any time.
    Random,
    /// Whole episodes, `--streaming-buffer` open at a time.
    Streaming,
}

impl WorkerMode {
    /// The value of `--worker`.
    pub fn flag(self) -> &'static str {
        match self {
            WorkerMode::Random => "random",
            WorkerMode::Streaming => "streaming",
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(subcommand)]
        bench: BenchCommand,
    }

    #[test]
    fn the_flags_hold_together() {
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from(["bench", "load", "--worker", "streaming", "--dataset", "d"])
            .expect("a worker command line");
        assert!(matches!(
            cli.bench,
            BenchCommand::Load(BenchLoadArgs {
                worker: Some(WorkerMode::Streaming),
                ..
            })
        ));
    }

    #[test]
    fn what_a_child_is_passed_is_what_its_parser_takes() {
        for c in Compression::value_variants() {
            let name = c.to_possible_value().map(|v| v.get_name().to_string());
            assert_eq!(name.as_deref(), Some(c.flag()));
        }
        for m in WorkerMode::value_variants() {
            let name = m.to_possible_value().map(|v| v.get_name().to_string());
            assert_eq!(name.as_deref(), Some(m.flag()));
        }
    }
}
