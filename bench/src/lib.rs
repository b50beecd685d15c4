//! scaledp's benchmarks, run by `scaledp bench <name>`: one module per benchmark, each with a
//! `run(args) -> Result<Outcome>` that prints its figures on stdout (progress and child output
//! go to stderr).
//!
//! - [`BenchCommand::Record`]: a soak of the recorder, a child process recording the
//!   reference load (2 ZED 1080p with depth, 3 RealSense with depth, 2 arms at 500 Hz, /tf,
//!   about 1.1 GB/s, or a fraction of it) over loopback in episodes back to back; messages
//!   sent vs recorded per topic, resident memory over time, CPU share, MB/s written.
//! - [`BenchCommand::Convert`]: generated recordings converted by a `scaledp convert` child;
//!   frames/s, MB/s, peak memory, beside the usual single-process Python route, the same
//!   conversion bucket to bucket on a loopback S3 endpoint, and the converter's floor.
//! - [`BenchCommand::Load`]: one shuffled loader epoch over a generated dataset; samples/s,
//!   images/s, MB/s, peak memory, beside pure JPEG decoding, the Python module and LeRobot's
//!   DataLoader, then a streaming epoch over a larger dataset.
//! - [`BenchCommand::Train`]: ScaleDP-Ti training on a converted simulated dataset in process;
//!   samples/s and the data-wait share, the same model in PyTorch from the same weights, and
//!   DDIM-10 latency per chunk for Ti and S.
//!
//! A new benchmark is one more module and one more [`BenchCommand`] variant.
//!
//! **The `scaledp` executable.** Each benchmark measures the product as a child process, so its
//! time and memory are its own: it runs [`std::env::current_exe`] with `bench record --worker`,
//! `convert` or `bench load --worker`. Call [`run`] from the `scaledp` binary (or one with the same
//! subcommands).
//!
//! **Python.** The scripts of the Python routes are compiled in and written to a temporary
//! directory at run time; their interpreter is `--python`, else the venv's variable, else the
//! venv in the workspace root found from the current directory upward (the lookup is
//! `scaledp_testkit::Venv`). A route that cannot run prints why and what to run instead of a
//! figure.
//!
//! Errors are `anyhow`: this is an application in library form, whose errors the CLI reports
//! once and turns into an exit code.

mod args;
mod convert;
mod convert_run;
mod convert_s3;
mod convert_video;
mod disk;
mod load;
mod python;
mod record;
mod synth;
mod train;

pub use args::{
    BenchCommand, BenchConvertArgs, BenchLoadArgs, BenchRecordArgs, BenchTrainArgs, BenchVideo,
    Compression, WorkerMode,
};

/// How a benchmark that ran to the end went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Every figure was measured.
    Completed,
    /// It finished, but data was lost on the way (`bench record`: messages the recorder did not
    /// write); the CLI exits with 3.
    DataLost,
}

/// Runs one benchmark.
pub fn run(command: BenchCommand) -> anyhow::Result<Outcome> {
    match command {
        BenchCommand::Record(args) => record::run(args),
        BenchCommand::Convert(args) => convert::run(args),
        BenchCommand::Load(args) => load::run(args),
        BenchCommand::Train(args) => train::run(args),
    }
}
