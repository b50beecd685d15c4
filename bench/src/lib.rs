//! scaledp's benchmarks, run by `scaledp bench <name>` (moved here from the CLI).

mod args;
mod convert;
mod load;
mod python;
mod record;

pub use args::{BenchCommand, BenchConvertArgs, BenchLoadArgs, BenchRecordArgs, Compression};

/// How a benchmark that ran to the end went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Every figure was measured.
    Completed,
    /// It finished, but data was lost on the way; the CLI exits with 3.
    DataLost,
}

/// Runs one benchmark.
pub fn run(command: BenchCommand) -> anyhow::Result<Outcome> {
    match command {
        BenchCommand::Record(args) => record::record(args),
        BenchCommand::Convert(args) => convert::run(args),
        BenchCommand::Load(args) => load::run(args),
    }
}
