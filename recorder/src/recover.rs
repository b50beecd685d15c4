//! Turns a recording cut short (`kill -9`, power loss, full disk) into a valid MCAP file.
//!
//! Streams the input record by record (never loading it whole), keeps every schema, channel,
//! metadata record and every message of every complete chunk, and stops at the first record that
//! is cut or corrupt.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Read};
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, Result};

/// What a recovery kept.
#[derive(Debug, Clone, PartialEq)]
pub struct RecoverySummary {
    /// The file written.
    pub output: PathBuf,
    /// Messages kept.
    pub messages: u64,
    /// Metadata records kept.
    pub metadata: u64,
    /// Log time of the last message kept (ns), 0 when none.
    pub last_log_time_ns: u64,
    /// Why reading stopped early, when it did (the part after that point is lost).
    pub stopped_at: Option<String>,
}

/// Where `recover` writes by default: `episode_000001.mcap.partial` → `episode_000001.mcap`,
/// anything else → `<stem>.recovered.mcap`.
pub fn default_output(input: &Path) -> PathBuf {
    let name = input
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("recording");
    match name.strip_suffix(".partial") {
        Some(base) if base.ends_with(".mcap") => input.with_file_name(base),
        _ => input.with_file_name(format!("{}.recovered.mcap", name.trim_end_matches(".mcap"))),
    }
}

/// Recovers `input` into `output` (which must not exist).
pub fn recover(input: &Path, output: &Path) -> Result<RecoverySummary> {
    if output.exists() {
        return Err(Error::Io {
            path: output.into(),
            source: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "output exists; not overwriting it",
            ),
        });
    }
    let mut src = File::open(input).map_err(Error::io(input))?;
    // Not `<output>.partial`: for the default output that is the input itself.
    let mut tmp = output.as_os_str().to_owned();
    tmp.push(".recovering");
    let tmp = PathBuf::from(tmp);
    if tmp == input {
        return Err(Error::Io {
            path: input.into(),
            source: std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "input and scratch file are the same",
            ),
        });
    }
    let options = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("scaledp-recover ", env!("CARGO_PKG_VERSION")))
        .compression(Some(mcap::Compression::Lz4));
    let mut out = options
        .create(BufWriter::new(File::create(&tmp).map_err(Error::io(&tmp))?))
        .map_err(Error::mcap(&tmp))?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_emit_chunks(false),
    );
    let mut summary = RecoverySummary {
        output: output.into(),
        messages: 0,
        metadata: 0,
        last_log_time_ns: 0,
        stopped_at: None,
    };
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(e) => {
                summary.stopped_at = Some(e.to_string());
                break;
            }
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                let got = src.read(reader.insert(n)).map_err(Error::io(input))?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                let record = match mcap::parse_record(opcode, data) {
                    Ok(r) => r,
                    Err(e) => {
                        summary.stopped_at = Some(e.to_string());
                        break;
                    }
                };
                let written = match record {
                    Record::Schema { header, data } => out
                        .add_schema_with_id(header.id, &header.name, &header.encoding, &data)
                        .map(drop),
                    Record::Channel(c) => out
                        .add_channel_with_id(
                            c.id,
                            c.schema_id,
                            &c.topic,
                            &c.message_encoding,
                            &c.metadata,
                        )
                        .map(drop),
                    Record::Message { header, data } => {
                        summary.messages += 1;
                        summary.last_log_time_ns = summary.last_log_time_ns.max(header.log_time);
                        out.write_to_known_channel(&header, &data)
                    }
                    Record::Metadata(m) => {
                        summary.metadata += 1;
                        out.write_metadata(&m)
                    }
                    _ => Ok(()),
                };
                written.map_err(Error::mcap(&tmp))?;
            }
        }
    }
    let mut note = BTreeMap::from([
        ("source".to_string(), input.display().to_string()),
        ("messages_kept".to_string(), summary.messages.to_string()),
    ]);
    if let Some(why) = &summary.stopped_at {
        note.insert("stopped_at".into(), why.clone());
    }
    out.write_metadata(&mcap::records::Metadata {
        name: "scaledp.recovery".into(),
        metadata: note,
    })
    .map_err(Error::mcap(&tmp))?;
    out.finish().map_err(Error::mcap(&tmp))?;
    drop(out);
    std::fs::rename(&tmp, output).map_err(Error::io(output))?;
    Ok(summary)
}
