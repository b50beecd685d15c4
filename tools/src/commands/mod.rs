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

use crate::cli::{Command, CompressionArg, ExitStatus, NetArgs};

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
        Command::Train(args) => train::run(args),
        Command::Predict(args) => predict::run(args),
        Command::Serve(args) => serve::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Demo(args) => demo::run(args),
        Command::View(args) => view::run(args),
    }
}

fn zenoh_config(net: &NetArgs, default_listen: &[String]) -> Result<zenoh::Config> {
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

fn compression(c: CompressionArg) -> scaledp_recorder::Compression {
    match c {
        CompressionArg::None => scaledp_recorder::Compression::None,
        CompressionArg::Lz4 => scaledp_recorder::Compression::Lz4,
        CompressionArg::Zstd => scaledp_recorder::Compression::Zstd,
    }
}

/// A flag set by Ctrl-C (SIGINT) or SIGTERM.
fn interrupt_flag() -> std::sync::Arc<std::sync::atomic::AtomicBool> {
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
fn free_port() -> Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}
