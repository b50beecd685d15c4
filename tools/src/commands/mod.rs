//! One module per subcommand; `dispatch` picks it.

mod collect;
mod convert;
mod demo;
pub(crate) mod eval;
pub(crate) mod predict;
mod record;
mod recover;
pub(crate) mod serve;
mod sim;
pub(crate) mod train;
mod view;

use anyhow::Result;

use crate::cli::{Command, ExitStatus};

/// Runs one parsed command.
pub fn dispatch(command: Command) -> Result<ExitStatus> {
    match command {
        Command::Sim(args) => sim::run(args),
        Command::Collect(args) => collect::run(args),
        Command::Record(args) => record::run(args),
        Command::Recover(args) => recover::run(args),
        Command::Convert(args) => convert::run(args),
        Command::Dataset(crate::cli::DatasetCommand::Merge(args)) => convert::merge(args),
        Command::Bench(cmd) => scaledp_bench::run(cmd).map(ExitStatus::from),
        Command::Train(args) => train::run(*args),
        Command::Predict(args) => predict::run(args),
        Command::Serve(args) => serve::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Experiment(cmd) => scaledp_experiment::run(cmd, &crate::shared::interrupt_flag())
            .map(|()| ExitStatus::Success),
        Command::Demo(args) => demo::run(args),
        Command::View(args) => view::run(args),
    }
}
