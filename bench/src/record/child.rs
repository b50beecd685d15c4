//! The benchmark's side of the recorder worker (see `worker`): the child process, its
//! commands, its latest status and its events, its resident memory and CPU time from /proc.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, Command as Process, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;

use crate::Compression;

/// The running worker.
pub struct Worker {
    child: Child,
    stdin: ChildStdin,
    events: mpsc::Receiver<Value>,
    status: Arc<Mutex<Option<Value>>>,
}

/// `VmRSS` of process `pid` (bytes).
pub fn vm_rss(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

impl Worker {
    /// Starts `exe bench record --worker` on `out` (which holds `rig.toml`), connecting to
    /// `endpoint`, with the soak's compression, episode length and disk floor (GB); its stderr
    /// (the recorder's log) goes to ours.
    pub fn spawn(
        exe: &Path,
        out: &Path,
        endpoint: &str,
        compression: Compression,
        episode_s: f64,
        min_free_gb: f64,
    ) -> Result<Self> {
        let mut cmd = Process::new(exe);
        if std::env::var_os("RUST_LOG").is_none() {
            // Warnings only, but not the one each episode's start gives: the load is off between
            // episodes (so that every message sent is counted in one), so every topic is silent
            // when an episode starts.
            cmd.env("RUST_LOG", "warn,scaledp_recorder::writer::start=error");
        }
        let mut child = cmd
            .args(["bench", "record", "-q", "--worker", "--endpoint", endpoint])
            .args(["--compression", compression.flag()])
            .args(["--episode-seconds", &episode_s.to_string()])
            .args(["--min-free-gb", &min_free_gb.to_string()])
            .arg("--out")
            .arg(out)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting the recorder worker {}", exe.display()))?;
        let stdin = child.stdin.take().context("the worker's stdin")?;
        let stdout = child.stdout.take().context("the worker's stdout")?;
        let (tx, events) = mpsc::channel();
        let status = Arc::new(Mutex::new(None));
        let latest = status.clone();
        std::thread::Builder::new()
            .name("worker:stdout".into())
            .spawn(move || {
                for line in BufReader::new(stdout).lines() {
                    let Ok(line) = line else { break };
                    let Ok(v) = serde_json::from_str::<Value>(&line) else {
                        tracing::warn!("recorder worker: {line}");
                        continue;
                    };
                    if v.get("status").is_some() {
                        if let Ok(mut s) = latest.lock() {
                            *s = Some(v["status"].clone());
                        }
                    } else if tx.send(v).is_err() {
                        break;
                    }
                }
            })?;
        Ok(Self {
            child,
            stdin,
            events,
            status,
        })
    }

    /// The worker's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends a command line.
    pub fn send(&mut self, command: &str) -> Result<()> {
        writeln!(self.stdin, "{command}")
            .and_then(|()| self.stdin.flush())
            .with_context(|| format!("sending '{command}' to the recorder worker"))
    }

    /// The worker's latest status (see `worker`).
    pub fn status(&self) -> Option<Value> {
        self.status.lock().ok().and_then(|s| s.clone())
    }

    /// Waits up to `timeout` for event `name`; a `failed` event or the worker's end is an
    /// error, other events are logged and passed over.
    pub fn wait_event(&mut self, name: &str, timeout: Duration) -> Result<Value> {
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.events.recv_timeout(left) {
                Ok(v) if v["event"] == name => return Ok(v),
                Ok(v) if v["event"] == "failed" => {
                    bail!("the recorder failed episode {}: {}", v["index"], v["error"])
                }
                Ok(v) if v["event"] == "refused" => {
                    bail!("the recorder refused to start: {}", v["reason"])
                }
                Ok(v) => {
                    tracing::info!("recorder: {}", v["what"].as_str().unwrap_or(&v.to_string()))
                }
                Err(mpsc::RecvTimeoutError::Timeout) => break,
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    let code = self.child.wait().ok().and_then(|s| s.code());
                    return Err(anyhow!(
                        "the recorder worker ended (exit code {code:?}) while waiting for '{name}'"
                    ));
                }
            }
        }
        bail!("no '{name}' from the recorder worker within {timeout:?}")
    }

    /// Waits up to `timeout` for the worker to exit after `quit`; kills it past that.
    pub fn finish(mut self, timeout: Duration) -> Result<Option<i32>> {
        let _ = self.send("quit");
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.child.try_wait()? {
                return Ok(s.code());
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                bail!("the recorder worker did not exit within {timeout:?} of 'quit'; killed");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        // An error on the way leaves no recorder running.
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}
