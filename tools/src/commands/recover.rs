//! `scaledp recover FILE`: repair a recording cut short by a crash.

use anyhow::{Context, Result};

use crate::cli::{ExitStatus, RecoverArgs};

pub fn run(args: RecoverArgs) -> Result<ExitStatus> {
    let output = args
        .output
        .unwrap_or_else(|| scaledp_recorder::default_output(&args.input));
    let s = scaledp_recorder::recover(&args.input, &output)
        .with_context(|| format!("recovering {}", args.input.display()))?;
    println!(
        "{}: {} messages, {} metadata records kept",
        s.output.display(),
        s.messages,
        s.metadata
    );
    match s.stopped_at {
        Some(why) => {
            eprintln!(
                "{}: the rest was cut or corrupt ({why}); lost from log time {} ns on",
                args.input.display(),
                s.last_log_time_ns
            );
            Ok(ExitStatus::DataLost)
        }
        None => Ok(ExitStatus::Success),
    }
}
