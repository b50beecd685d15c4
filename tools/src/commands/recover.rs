//! `scaledp recover FILE`: repair a recording cut short by a crash. An input or output in
//! object storage (`s3://…`) goes through the work directory: the object is downloaded, the
//! recovered file uploaded whole (an existing output object is never replaced).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use scaledp_converter::{Location, ObjectUrl};
use scaledp_store::Bucket;

use crate::cli::{ExitStatus, RecoverArgs};
use crate::shared::location;

/// The default output of `input`: its name without `.partial`, or `<stem>.recovered.mcap`.
fn default_output(input: &Location) -> Location {
    match input {
        Location::Local(p) => Location::Local(scaledp_recorder::default_output(p)),
        Location::Object(u) => {
            let name = scaledp_recorder::default_output(Path::new(u.file_name()));
            let name = name.to_string_lossy();
            let parent = u.key.rsplit_once('/').map_or("", |(p, _)| p);
            let key = if parent.is_empty() {
                name.into_owned()
            } else {
                format!("{parent}/{name}")
            };
            Location::Object(ObjectUrl {
                bucket: u.bucket.clone(),
                key,
            })
        }
    }
}

pub fn run(args: RecoverArgs) -> Result<ExitStatus> {
    let input = location(&args.input)?;
    let output = match &args.output {
        Some(o) => location(o)?,
        None => default_output(&input),
    };
    let work_dir = args.work_dir.clone().unwrap_or_else(std::env::temp_dir);
    let tmp = tempfile::Builder::new()
        .prefix("scaledp-recover-")
        .tempdir_in(&work_dir)
        .with_context(|| format!("creating a directory in {}", work_dir.display()))?;
    let local_input: PathBuf = match &input {
        Location::Local(p) => p.clone(),
        Location::Object(u) => {
            let bucket = Bucket::connect(&u.bucket)?;
            let Some(info) = bucket.head(u)? else {
                bail!("{u}: no such object");
            };
            let local = tmp.path().join(u.file_name());
            bucket.download(&info, &local)?;
            local
        }
    };
    let local_output = match &output {
        Location::Local(p) => p.clone(),
        Location::Object(u) => {
            if Bucket::connect(&u.bucket)?.head(u)?.is_some() {
                bail!("{u}: output exists; not overwriting it");
            }
            tmp.path().join(format!("recovered-{}", u.file_name()))
        }
    };
    let s = scaledp_recorder::recover(&local_input, &local_output)
        .with_context(|| format!("recovering {input}"))?;
    if let Location::Object(u) = &output {
        Bucket::connect(&u.bucket)?.upload(&local_output, u)?;
    }
    println!(
        "{output}: {} messages, {} metadata records kept",
        s.messages, s.metadata
    );
    match s.stopped_at {
        Some(why) => {
            eprintln!(
                "{input}: the rest was cut or corrupt ({why}); lost from log time {} ns on",
                s.last_log_time_ns
            );
            Ok(ExitStatus::DataLost)
        }
        None => Ok(ExitStatus::Success),
    }
}
