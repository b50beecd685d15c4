//! What a process costs, from Linux's /proc: CPU seconds, peak resident memory, the machine's
//! load; and [`measure`], which runs a child process to the end while sampling them.
//!
//! Every figure is `None` where /proc cannot be read (another OS, a process already reaped).

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::{Error, Result};

/// Clock ticks per second of /proc's CPU times (`USER_HZ`, fixed at 100 for user space).
const USER_HZ: f64 = 100.0;

/// User + system CPU seconds of process `pid` so far.
pub fn cpu_seconds(pid: u32) -> Option<f64> {
    cpu_seconds_at(Path::new(&format!("/proc/{pid}/stat")))
}

/// User + system CPU seconds from a `stat` file of /proc: a process's
/// (`/proc/<pid>/stat`) or one thread's (`/proc/<pid>/task/<tid>/stat`).
pub fn cpu_seconds_at(stat: &Path) -> Option<f64> {
    let stat = std::fs::read_to_string(stat).ok()?;
    // The command name, in parentheses, may hold spaces: fields are counted after it.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / USER_HZ)
}

/// `VmHWM`, the peak resident set size of process `pid`, in bytes.
pub fn vm_hwm(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The machine's 1-minute load average.
pub fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// What one measured child process did.
#[derive(Debug)]
pub struct Measured {
    /// How it exited.
    pub status: ExitStatus,
    /// Wall seconds from spawn to exit.
    pub wall_s: f64,
    /// The last `VmHWM` seen (bytes).
    pub peak_rss: Option<u64>,
    /// The last user + system CPU seconds seen.
    pub cpu_s: Option<f64>,
    /// Its stdout, line by line.
    pub stdout: Vec<String>,
    /// Its stderr, line by line.
    pub stderr: Vec<String>,
}

/// Runs `cmd` to the end (killing it after `timeout`), copying its output line by line to our
/// stderr (indented by `  | `) and keeping it, and samples its peak memory and CPU time every
/// 20 ms.
pub fn measure(mut cmd: Command, timeout: Option<Duration>) -> Result<Measured> {
    let program = cmd.get_program().to_string_lossy().into_owned();
    let failed = |source| Error::Process {
        program: program.clone(),
        source,
    };
    let t0 = Instant::now();
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(failed)?;
    let out = forward(child.stdout.take());
    let err = forward(child.stderr.take());
    let (mut peak_rss, mut cpu_s) = (None, None);
    let status = loop {
        peak_rss = vm_hwm(child.id()).or(peak_rss);
        cpu_s = cpu_seconds(child.id()).or(cpu_s);
        if let Some(status) = child.try_wait().map_err(failed)? {
            break status;
        }
        if timeout.is_some_and(|t| t0.elapsed() > t) {
            child.kill().ok();
            child.wait().ok();
            return Err(Error::TimedOut {
                program,
                seconds: t0.elapsed().as_secs_f64(),
            });
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let wall_s = t0.elapsed().as_secs_f64();
    let join = |h: JoinHandle<Vec<String>>| h.join().unwrap_or_default();
    Ok(Measured {
        status,
        wall_s,
        peak_rss,
        cpu_s,
        stdout: join(out),
        stderr: join(err),
    })
}

/// Copies a child's pipe line by line to our stderr and keeps the lines.
fn forward<R: Read + Send + 'static>(pipe: Option<R>) -> JoinHandle<Vec<String>> {
    std::thread::spawn(move || {
        let mut lines = Vec::new();
        if let Some(pipe) = pipe {
            for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                eprintln!("  | {line}");
                lines.push(line);
            }
        }
        lines
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn this_process_has_figures_on_linux() {
        if !Path::new("/proc/self/stat").exists() {
            return;
        }
        let me = std::process::id();
        assert!(cpu_seconds(me).is_some_and(|s| s >= 0.0));
        assert!(vm_hwm(me).is_some_and(|b| b > 0));
        assert!(load_average().is_some_and(|l| l >= 0.0));
    }

    #[test]
    fn a_measured_child_gives_its_output_status_and_figures() {
        let mut cmd = Command::new("sh");
        cmd.args(["-c", "echo one; echo two >&2; exit 3"]);
        let m = measure(cmd, Some(Duration::from_secs(30))).expect("sh runs");
        assert_eq!(m.status.code(), Some(3));
        assert_eq!(m.stdout, ["one"]);
        assert_eq!(m.stderr, ["two"]);
        assert!(m.wall_s > 0.0);
    }

    #[test]
    fn a_child_past_its_limit_is_killed_and_missing_programs_are_named() {
        let mut cmd = Command::new("sleep");
        cmd.arg("30");
        let e = measure(cmd, Some(Duration::from_millis(100))).expect_err("killed");
        assert!(matches!(e, Error::TimedOut { .. }), "{e}");
        let e = measure(Command::new("/no/such/program"), None).expect_err("not found");
        assert!(e.to_string().starts_with("/no/such/program: "), "{e}");
    }
}
