//! Where rerun streams go: a spawned viewer, a viewer at an address, or an `.rrd` file. One
//! [`Sink`] serves every recording of a session (one per episode), so several inputs end up in
//! one viewer or one file. A file is written as `<name>.partial` and renamed only when every
//! recording was written and flushed, so a failure never leaves a half-written `.rrd` under the
//! name asked for.

use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use rerun::sink::{FileSink, LogSink, SinkFlushError};
use rerun::RecordingStream;

use crate::error::{Error, Result};

/// The rerun application id of every stream scaledp writes.
pub const APPLICATION_ID: &str = "scaledp";

/// How long a flush may take before the viewer counts as unreachable.
const FLUSH_TIMEOUT: Duration = Duration::from_secs(60);

/// Where the streams go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A rerun viewer on this machine: the one already listening on rerun's default port, else
    /// a new one spawned from the `rerun` binary on `PATH` (the `rerun-sdk` wheel installs it).
    Spawn,
    /// An `.rrd` file (opened later with `rerun out.rrd`).
    Save(PathBuf),
    /// A viewer already running, e.g. on another machine:
    /// `rerun+http://host:9876/proxy` (rerun's own URL form; `host:port` alone also works).
    Connect(String),
}

/// Image bytes logged between two flushes: rerun's batcher and sinks queue whatever is logged
/// faster than they write or send it, so a long recording would otherwise pile up in memory.
const FLUSH_EVERY_BYTES: usize = 64 << 20;

/// Flushes a stream every [`FLUSH_EVERY_BYTES`] logged: memory stays bounded by that much
/// whatever the input's size, and the writer (file or network) sets the pace.
#[derive(Debug, Default)]
pub(crate) struct Backpressure {
    pending: usize,
}

impl Backpressure {
    /// Counts `bytes` just logged to `rec`; waits for the sink when enough are pending.
    pub fn logged(&mut self, rec: &RecordingStream, bytes: usize) -> Result<()> {
        self.pending += bytes;
        if self.pending < FLUSH_EVERY_BYTES {
            return Ok(());
        }
        self.pending = 0;
        rec.flush_with_timeout(FLUSH_TIMEOUT)
            .map_err(|e| Error::Rerun(format!("the viewer or file does not keep up: {e}")))
    }
}

/// The sink of a session: opens a stream per recording and finishes them together.
pub(crate) struct Sink {
    kind: Kind,
}

enum Kind {
    Grpc(String),
    File {
        file: Arc<FileSink>,
        partial: PathBuf,
        out: PathBuf,
    },
}

/// One file shared by the streams of several recordings (a file holds many recordings).
struct SharedFile(Arc<FileSink>);

impl LogSink for SharedFile {
    fn send(&self, msg: rerun::log::LogMsg) {
        self.0.send(msg);
    }
    fn flush_blocking(&self, timeout: Duration) -> Result<(), SinkFlushError> {
        LogSink::flush_blocking(&*self.0, timeout)
    }
}

/// `rerun+http://host:port/proxy` for any of the accepted address forms.
pub(crate) fn grpc_url(url: &str) -> String {
    if url.contains("://") {
        url.to_string()
    } else {
        format!("rerun+http://{}/proxy", url.trim_end_matches('/'))
    }
}

/// `host:port` of a gRPC URL.
fn host_port(url: &str) -> Option<String> {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let authority = rest.split('/').next()?;
    if authority.is_empty() {
        return None;
    }
    Some(if authority.contains(':') {
        authority.to_string()
    } else {
        format!("{authority}:{}", rerun::DEFAULT_SERVER_PORT)
    })
}

/// Fails unless something accepts TCP connections at the URL's host and port.
pub(crate) fn check_reachable(url: &str) -> Result<()> {
    let unreachable = |reason: String| Error::Unreachable {
        url: url.to_string(),
        reason,
    };
    let hp = host_port(url).ok_or_else(|| unreachable("no host in the address".into()))?;
    let addrs: Vec<_> = hp
        .to_socket_addrs()
        .map_err(|e| unreachable(format!("{hp}: {e}")))?
        .collect();
    let mut last = format!("{hp} resolves to no address");
    for a in addrs {
        match TcpStream::connect_timeout(&a, Duration::from_secs(3)) {
            Ok(_) => return Ok(()),
            Err(e) => last = format!("{a}: {e}"),
        }
    }
    Err(unreachable(last))
}

/// Whether an executable named `name` is on `PATH`.
fn on_path(name: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|paths| {
        std::env::split_paths(&paths).any(|dir| {
            let p = dir.join(name);
            p.is_file()
                && std::fs::metadata(&p).is_ok_and(|m| {
                    use std::os::unix::fs::PermissionsExt;
                    m.permissions().mode() & 0o111 != 0
                })
        })
    })
}

/// `out.rrd` → `out.rrd.partial`.
fn partial_path(out: &Path) -> PathBuf {
    let mut name = out.as_os_str().to_os_string();
    name.push(".partial");
    name.into()
}

impl Sink {
    /// Opens the target: spawns or checks the viewer, or creates the partial file.
    pub fn open(target: &Target) -> Result<Self> {
        let kind = match target {
            Target::Spawn => {
                let opts = rerun::SpawnOptions::default();
                let url = format!("rerun+http://{}/proxy", opts.connect_addr());
                if check_reachable(&url).is_err() {
                    if !on_path(&opts.executable_name) {
                        return Err(Error::NoViewer);
                    }
                    rerun::spawn(&opts).map_err(|e| match e {
                        rerun::SpawnError::ExecutableNotFoundInPath { .. } => Error::NoViewer,
                        e => Error::rerun(e),
                    })?;
                }
                Kind::Grpc(url)
            }
            Target::Connect(url) => {
                let url = grpc_url(url);
                check_reachable(&url)?;
                Kind::Grpc(url)
            }
            Target::Save(out) => {
                if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
                }
                let partial = partial_path(out);
                let file = FileSink::new(&partial).map_err(|e| Error::Io {
                    path: partial.clone(),
                    source: std::io::Error::other(e.to_string()),
                })?;
                Kind::File {
                    file: Arc::new(file),
                    partial,
                    out: out.clone(),
                }
            }
        };
        Ok(Self { kind })
    }

    /// A new recording named `name` (shown in the viewer's recording list) with `id`; logging
    /// the same id twice adds to one recording.
    pub fn stream(&self, id: &str, name: &str) -> Result<RecordingStream> {
        let builder = rerun::RecordingStreamBuilder::new(APPLICATION_ID)
            .recording_id(id)
            .send_properties(true) // an explicit id turns them off; they carry the name
            .recording_name(name);
        match &self.kind {
            Kind::Grpc(url) => builder.connect_grpc_opts(url.clone()),
            Kind::File { file, .. } => builder.buffered().inspect(|rec| {
                rec.set_sink(Box::new(SharedFile(file.clone())));
            }),
        }
        .map_err(Error::rerun)
    }

    /// Flushes and closes every stream; renames the file into place. On error the partial
    /// file is removed.
    pub fn finish(self, streams: Vec<RecordingStream>) -> Result<Option<PathBuf>> {
        let mut failure = None;
        for rec in &streams {
            if let Err(e) = rec.flush_with_timeout(FLUSH_TIMEOUT) {
                failure.get_or_insert(e.to_string());
            }
        }
        drop(streams);
        match self.kind {
            Kind::Grpc(url) => match failure {
                Some(reason) => Err(Error::Unreachable { url, reason }),
                None => Ok(None),
            },
            Kind::File { file, partial, out } => {
                let written = finish_file(file, failure);
                match written
                    .and_then(|()| std::fs::rename(&partial, &out).map_err(|e| e.to_string()))
                {
                    Ok(()) => Ok(Some(out)),
                    Err(reason) => {
                        let _ = std::fs::remove_file(&partial);
                        Err(Error::Io {
                            path: out,
                            source: std::io::Error::other(reason),
                        })
                    }
                }
            }
        }
    }

    /// Removes a partial file after a failure elsewhere (nothing half-written stays).
    pub fn abandon(self, streams: Vec<RecordingStream>) {
        drop(streams);
        if let Kind::File { file, partial, .. } = self.kind {
            let _ = finish_file(file, None);
            let _ = std::fs::remove_file(&partial);
        }
    }
}

/// Waits until no stream holds the file any more, flushes it and writes its footer.
fn finish_file(file: Arc<FileSink>, failure: Option<String>) -> std::result::Result<(), String> {
    // Streams release their sinks on their own threads shortly after they are dropped.
    let deadline = std::time::Instant::now() + FLUSH_TIMEOUT;
    while Arc::strong_count(&file) > 1 && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    let flushed = file
        .flush_blocking(FLUSH_TIMEOUT)
        .map_err(|e| e.to_string());
    match Arc::try_unwrap(file) {
        Ok(f) => drop(f), // joins the writer thread: the footer is on disk
        Err(_) => return Err("the file is still in use by a stream".into()),
    }
    match failure {
        Some(reason) => Err(reason),
        None => flushed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses() {
        assert_eq!(
            grpc_url("10.0.0.2:9876"),
            "rerun+http://10.0.0.2:9876/proxy"
        );
        assert_eq!(grpc_url("rerun+http://a:1/proxy"), "rerun+http://a:1/proxy");
        assert_eq!(host_port("rerun+http://a:1/proxy").as_deref(), Some("a:1"));
        assert_eq!(host_port("rerun+http://a/proxy").as_deref(), Some("a:9876"));
        assert_eq!(host_port("rerun+http:///proxy"), None);
    }

    #[test]
    fn an_address_nobody_listens_on_is_unreachable() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("a free port");
        let url = format!("rerun+http://127.0.0.1:{port}/proxy");
        let e = check_reachable(&url).expect_err("nobody listens");
        assert!(
            e.to_string().starts_with("cannot reach a rerun viewer at "),
            "{e}"
        );
    }
}
