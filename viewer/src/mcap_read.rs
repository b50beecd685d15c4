//! An MCAP file read forward once, message by message, with the `mcap` crate's sans-io reader:
//! memory is one chunk (our recorder closes ~8 MB chunks), so a multi-GB recording starts
//! showing at once. A file cut short (a `.partial` from a crash, or one still being written)
//! yields every complete record and then reports where it stopped.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, Result};

/// Largest record accepted (a chunk, uncompressed).
const MAX_RECORD: usize = 1 << 30;

/// One message as it streams past.
pub(crate) struct Message<'a> {
    /// Topic, with its leading `/`.
    pub topic: &'a str,
    /// Schema name in ROS 2 form (`pkg/msg/Type`).
    pub message_type: &'a str,
    /// Receive time (ns).
    pub log_time_ns: u64,
    /// The CDR payload.
    pub data: &'a [u8],
}

/// What a file held besides its messages.
#[derive(Debug, Default)]
pub(crate) struct Ending {
    /// Metadata records by name, in file order of their names.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Why reading stopped early (a truncated or corrupt file), if it did.
    pub cut: Option<String>,
    /// Messages skipped because their channel is not `cdr`.
    pub not_cdr: u64,
}

/// Callbacks of [`read`]: a metadata record (as soon as it is read, so the episode-start
/// record arrives before any message), and each message.
pub(crate) trait Visitor {
    /// A metadata record.
    fn metadata(&mut self, name: &str, record: &BTreeMap<String, String>) -> Result<()>;
    /// A message.
    fn message(&mut self, m: Message<'_>) -> Result<()>;
}

/// `sensor_msgs/Image` → `sensor_msgs/msg/Image`.
fn ros2_type(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        _ => name.to_string(),
    }
}

/// Reads `path` forward, calling `visitor` per metadata record and message.
pub(crate) fn read(path: &Path, visitor: &mut dyn Visitor) -> Result<Ending> {
    let file = std::fs::File::open(path).map_err(Error::io(path))?;
    let mut file = std::io::BufReader::with_capacity(1 << 20, file);
    let bad = |reason: String| Error::input(path.display(), reason);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(MAX_RECORD),
    );
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    // channel id → (topic, type, cdr)
    let mut channels: BTreeMap<u16, (String, String, bool)> = BTreeMap::new();
    let mut ending = Ending::default();
    let mut first = true;
    let mut read_any = false;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(e) if !read_any || first => return Err(bad(format!("not an MCAP file: {e}"))),
            Err(e) => {
                ending.cut = Some(format!("stopped at a corrupt or cut record: {e}"));
                break;
            }
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n);
                let got = file.read(buf).map_err(Error::io(path))?;
                reader.notify_read(got);
                if got == 0 && n > 0 {
                    // End of file before the reader was done: a cut file.
                    if first {
                        return Err(bad(
                            "not an MCAP file: empty or shorter than its magic".into()
                        ));
                    }
                    ending.cut = Some("the file ends before its summary (cut short?)".into());
                    break;
                }
                read_any = true;
            }
            LinearReadEvent::Record { data, opcode } => {
                let record = match mcap::parse_record(opcode, data) {
                    Ok(r) => r,
                    Err(e) => {
                        ending.cut = Some(format!("corrupt record: {e}"));
                        break;
                    }
                };
                if first {
                    first = false;
                    match &record {
                        Record::Header(h) if h.profile == "ros2" || h.profile.is_empty() => {}
                        Record::Header(h) => {
                            return Err(bad(format!(
                                "MCAP profile is '{}', expected 'ros2'",
                                h.profile
                            )))
                        }
                        _ => return Err(bad("not an MCAP file: no header record".into())),
                    }
                }
                match record {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, ros2_type(&header.name));
                    }
                    Record::Channel(c) => {
                        let ty = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        channels.insert(c.id, (c.topic, ty, c.message_encoding == "cdr"));
                    }
                    Record::Message { header, data } => {
                        let Some((topic, ty, cdr)) = channels.get(&header.channel_id) else {
                            continue;
                        };
                        if !cdr {
                            ending.not_cdr += 1;
                            continue;
                        }
                        visitor.message(Message {
                            topic,
                            message_type: ty,
                            log_time_ns: header.log_time,
                            data: &data,
                        })?;
                    }
                    Record::Metadata(m) => {
                        visitor.metadata(&m.name, &m.metadata)?;
                        ending.metadata.insert(m.name, m.metadata);
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(ending)
}
