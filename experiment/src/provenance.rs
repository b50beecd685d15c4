//! Where and what ran: the commit this binary was built from, the machine, the time, and the
//! one way results files are written (whole, through a `.partial` renamed over the old one).

use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

/// Where and what ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The commit the binary that ran was built from ([`git_revision`]).
    pub git_revision: String,
    /// CPU model, cores, memory.
    pub machine: String,
    /// When the arm's result was written (UTC, RFC 3339).
    pub finished_utc: String,
}

/// The commit this binary was built from (`-dirty` when its tree had changes then, `unknown`
/// when built outside a git checkout): what ran, whatever the checkout says by the time a long
/// run finishes. Read at compile time; the crate is rebuilt when HEAD or the index moves.
pub fn git_revision() -> String {
    git_version::git_version!(
        args = ["--always", "--dirty=-dirty", "--abbrev=40", "--match=^$"],
        fallback = "unknown"
    )
    .to_string()
}

impl Provenance {
    /// This binary's revision, this machine, now.
    pub fn now() -> Self {
        Provenance {
            git_revision: git_revision(),
            machine: machine(),
            finished_utc: now_utc(),
        }
    }
}

/// Writes `value` as pretty JSON to `path` through a `.partial` file renamed over it, so an
/// interrupted write leaves the earlier file whole.
pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = std::path::PathBuf::from(partial);
    std::fs::write(&partial, serde_json::to_vec_pretty(value)?)
        .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, path).with_context(|| format!("writing {}", path.display()))
}

/// The CPU model, core count and memory, from /proc.
pub fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemTotal"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or("? GiB".into(), |kb| format!("{:.0} GiB", kb / 1048576.0));
    format!("{cpu}, {cores} cores, {mem}")
}

/// Now as RFC 3339 UTC, to the second.
pub fn now_utc() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

#[cfg(test)]
mod tests {
    /// A full commit hash (a tag in the history must not turn it into `git describe`'s
    /// `tag-N-gHASH`), `-dirty` at most, or `unknown` outside a checkout.
    #[test]
    fn the_revision_is_a_full_commit() {
        let r = super::git_revision();
        let hash = r.strip_suffix("-dirty").unwrap_or(&r);
        assert!(
            r == "unknown" || (hash.len() == 40 && hash.chars().all(|c| c.is_ascii_hexdigit())),
            "{r}"
        );
    }
}
