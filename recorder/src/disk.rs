//! The disk guard: an episode starts only when the output disk has room for it, the session
//! says when less than a few minutes of recording are left, and an episode ends, whole and
//! readable, before the disk is full.
//!
//! The byte rate is what the previous episode took on disk per second, else what the topics
//! delivered over the last seconds; the length expected is the session's episode time, else
//! the longest episode so far, else [`DEFAULT_EPISODE_S`]. Free space comes from a
//! [`FreeSpace`] (statvfs by default; a test gives its own).

use std::path::Path;
use std::sync::Arc;

/// The length assumed for an episode before any has been recorded, without an episode time (s).
pub const DEFAULT_EPISODE_S: f64 = 60.0;
/// Recorded bytes per payload byte, before an episode has measured it (MCAP records, indexes).
const OVERHEAD: f64 = 1.05;
/// Room always left free: the open chunk, the write buffer, the summary section…
const MIN_RESERVE: u64 = 32 << 20;
/// …and this many seconds of recording.
const RESERVE_S: f64 = 3.0;

/// A directory's free bytes, or why they are unknown.
type Query = dyn Fn(&Path) -> std::io::Result<u64> + Send + Sync;

/// How much room a directory's disk has left for us (bytes). Cheap to clone.
#[derive(Clone)]
pub struct FreeSpace(Arc<Query>);

impl FreeSpace {
    /// Free space as `f` tells it (a test's full disk).
    pub fn new(f: impl Fn(&Path) -> std::io::Result<u64> + Send + Sync + 'static) -> Self {
        Self(Arc::new(f))
    }
    /// Free space for unprivileged users as the file system reports it (statvfs).
    pub fn system() -> Self {
        Self::new(|dir| {
            let s = rustix::fs::statvfs(dir)?;
            Ok(s.f_bavail.saturating_mul(s.f_frsize))
        })
    }
    /// The free bytes on `dir`'s disk.
    pub fn query(&self, dir: &Path) -> std::io::Result<u64> {
        (self.0)(dir)
    }
}

impl std::fmt::Debug for FreeSpace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("FreeSpace(..)")
    }
}

/// The guard's settings.
#[derive(Debug, Clone)]
pub(crate) struct DiskOptions {
    pub enabled: bool,
    /// The episode length the session plans (s).
    pub episode_s: Option<f64>,
    /// Warn below this many minutes of recording left.
    pub warn_minutes: f64,
    pub free_space: FreeSpace,
}

impl Default for DiskOptions {
    fn default() -> Self {
        Self {
            enabled: true,
            episode_s: None,
            warn_minutes: 5.0,
            free_space: FreeSpace::system(),
        }
    }
}

/// The disk as the guard last saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct DiskStatus {
    /// Free bytes on the output directory's disk.
    pub free_bytes: u64,
    /// Bytes per second an episode takes, when known.
    pub bytes_per_s: Option<f64>,
    /// Minutes of recording the free space holds (room kept free left out), when the rate is
    /// known.
    pub minutes_left: Option<f64>,
    /// Less than the warning's minutes left.
    pub low: bool,
}

/// `1.3 GB`, `820 MB`, `12 kB`.
pub(crate) fn bytes(n: f64) -> String {
    match n {
        n if n >= 1e9 => format!("{:.1} GB", n / 1e9),
        n if n >= 1e6 => format!("{:.0} MB", n / 1e6),
        n => format!("{:.0} kB", n / 1e3),
    }
}

/// The guard of one session.
#[derive(Debug)]
pub(crate) struct DiskGuard {
    opts: DiskOptions,
    /// Longest episode so far (s).
    longest_s: f64,
    /// Bytes per second on disk of the latest episode that lasted a second or more.
    disk_rate: Option<f64>,
    /// Warned that little is left (cleared when there is room again).
    warned: bool,
    /// A failed query was logged.
    query_failed: bool,
}

impl DiskGuard {
    pub fn new(opts: DiskOptions) -> Self {
        Self {
            opts,
            longest_s: 0.0,
            disk_rate: None,
            warned: false,
            query_failed: false,
        }
    }

    /// Free bytes on `dir`'s disk; None (logged once) when the query fails or the guard is off.
    fn free(&mut self, dir: &Path) -> Option<u64> {
        if !self.opts.enabled {
            return None;
        }
        // A directory not made yet (or removed meanwhile) is on its nearest ancestor's disk.
        let dir = dir.ancestors().find(|d| d.exists()).unwrap_or(dir);
        match self.opts.free_space.query(dir) {
            Ok(n) => Some(n),
            Err(e) => {
                if !std::mem::replace(&mut self.query_failed, true) {
                    tracing::warn!(
                        "{}: free space unknown ({e}): no disk guard while it is",
                        dir.display()
                    );
                }
                None
            }
        }
    }

    /// Bytes per second of recording: the previous episode's on disk, else the live payload
    /// rate with the file's overhead.
    fn rate(&self, live_bytes_per_s: Option<f64>) -> Option<f64> {
        self.disk_rate
            .or(live_bytes_per_s.map(|r| r * OVERHEAD))
            .filter(|r| *r > 0.0)
    }

    /// Room kept free at a byte rate.
    fn reserve(rate: Option<f64>) -> u64 {
        MIN_RESERVE.max((rate.unwrap_or(0.0) * RESERVE_S) as u64)
    }

    /// The length expected of the next episode and where it comes from.
    fn expected_s(&self) -> (f64, &'static str) {
        match self.opts.episode_s {
            Some(s) => (s, "the episode time"),
            None if self.longest_s > 0.0 => (self.longest_s, "the longest episode so far"),
            None => (DEFAULT_EPISODE_S, "the default length, no episode time set"),
        }
    }

    /// Whether episode `index` may start: Err is the line saying why not.
    pub fn check_start(
        &mut self,
        dir: &Path,
        index: u64,
        live_bytes_per_s: Option<f64>,
    ) -> Result<(), String> {
        let Some(free) = self.free(dir) else {
            return Ok(());
        };
        let rate = self.rate(live_bytes_per_s);
        let (secs, why) = self.expected_s();
        let needed = rate.unwrap_or(0.0) * secs + Self::reserve(rate) as f64;
        if (free as f64) >= needed {
            return Ok(());
        }
        let size = match rate {
            Some(r) => format!(
                "about {} ({secs:.0} s, {why}, at {}/s)",
                bytes(needed),
                bytes(r)
            ),
            None => format!("at least {}", bytes(needed)),
        };
        Err(format!(
            "episode {index} not started: it needs {size} and {} has {} free",
            dir.display(),
            bytes(free as f64)
        ))
    }

    /// While an episode is written: the line that ends it when the disk is about to be full.
    pub fn check_running(
        &mut self,
        dir: &Path,
        file: &Path,
        live_bytes_per_s: Option<f64>,
    ) -> Option<String> {
        let free = self.free(dir)?;
        let reserve = Self::reserve(self.rate(live_bytes_per_s));
        (free < reserve).then(|| {
            format!(
                "{}: ended early, the disk is full ({} free of the {} kept free to finish the file)",
                file.display(),
                bytes(free as f64),
                bytes(reserve as f64)
            )
        })
    }

    /// The disk's figures now, and a line when it has just become low on room.
    pub fn status(
        &mut self,
        dir: &Path,
        live_bytes_per_s: Option<f64>,
    ) -> (Option<DiskStatus>, Option<String>) {
        let Some(free) = self.free(dir) else {
            return (None, None);
        };
        let rate = self.rate(live_bytes_per_s);
        let minutes_left = rate.map(|r| free.saturating_sub(Self::reserve(rate)) as f64 / r / 60.0);
        let low = minutes_left.is_some_and(|m| m < self.opts.warn_minutes);
        let newly = low && !std::mem::replace(&mut self.warned, low);
        self.warned = low;
        let line = newly.then(|| {
            format!(
                "{} has {} free: {:.1} min of recording left",
                dir.display(),
                bytes(free as f64),
                minutes_left.unwrap_or(0.0)
            )
        });
        let status = DiskStatus {
            free_bytes: free,
            bytes_per_s: rate,
            minutes_left,
            low,
        };
        (Some(status), line)
    }

    /// An episode of `duration_s` took `bytes` on disk.
    pub fn finished(&mut self, bytes: u64, duration_s: f64) {
        self.longest_s = self.longest_s.max(duration_s);
        if duration_s >= 1.0 {
            self.disk_rate = Some(bytes as f64 / duration_s);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

    fn guard(free: &Arc<AtomicU64>, episode_s: Option<f64>) -> DiskGuard {
        let f = free.clone();
        DiskGuard::new(DiskOptions {
            enabled: true,
            episode_s,
            warn_minutes: 5.0,
            free_space: FreeSpace::new(move |_| Ok(f.load(Relaxed))),
        })
    }

    #[test]
    fn starts_only_with_room_and_ends_before_the_disk_is_full() {
        let free = Arc::new(AtomicU64::new(10_000_000_000));
        let dir = Path::new("/data");
        let mut g = guard(&free, None);
        // 10 MB/s live, no episode yet: 60 s × 10.5 MB/s + 32 MiB reserve ≈ 664 MB.
        assert_eq!(g.check_start(dir, 0, Some(10e6)), Ok(()));
        free.store(600_000_000, Relaxed);
        let e = g.check_start(dir, 0, Some(10e6)).unwrap_err();
        assert_eq!(
            e,
            "episode 0 not started: it needs about 664 MB (60 s, the default length, no episode \
             time set, at 10 MB/s) and /data has 600 MB free"
        );
        // A 20 s episode took 100 MB: 5 MB/s, the longest so far 20 s.
        g.finished(100_000_000, 20.0);
        assert_eq!(g.check_start(dir, 1, Some(10e6)), Ok(()));
        free.store(120_000_000, Relaxed);
        let e = g.check_start(dir, 1, None).unwrap_err();
        assert!(
            e.contains("(20 s, the longest episode so far, at 5 MB/s)"),
            "{e}"
        );
        // 120 MB free at 5 MB/s: (120 − 33.6) MB / 5 MB/s ≈ 0.3 min: low, said once.
        let (s, line) = g.status(dir, None);
        let s = s.unwrap();
        assert!(
            s.low && (s.minutes_left.unwrap() - 0.29).abs() < 0.01,
            "{s:?}"
        );
        assert!(line.unwrap().contains("/data has 120 MB free"));
        assert_eq!(g.status(dir, None).1, None);
        // Below the reserve mid-episode: the episode ends, naming its file.
        assert_eq!(g.check_running(dir, Path::new("/data/e.mcap"), None), None);
        free.store(20_000_000, Relaxed);
        let cut = g
            .check_running(dir, Path::new("/data/e.mcap"), None)
            .unwrap();
        assert!(
            cut.starts_with("/data/e.mcap: ended early, the disk is full"),
            "{cut}"
        );
        // A fixed episode time is what the next one needs.
        let mut g = guard(&free, Some(30.0));
        free.store(1_000_000_000, Relaxed);
        let e = g.check_start(dir, 4, Some(40e6)).unwrap_err();
        assert!(e.contains("(30 s, the episode time, at 42 MB/s)"), "{e}");
    }

    #[test]
    fn a_failing_query_turns_the_guard_off() {
        let mut g = DiskGuard::new(DiskOptions {
            free_space: FreeSpace::new(|_| Err(std::io::Error::other("no statvfs"))),
            ..DiskOptions::default()
        });
        assert_eq!(g.check_start(Path::new("/x"), 0, Some(1e9)), Ok(()));
        assert_eq!(g.status(Path::new("/x"), None), (None, None));
    }

    #[test]
    fn the_system_reports_free_space() {
        let dir = tempfile::tempdir().unwrap();
        let n = FreeSpace::system().query(dir.path()).unwrap();
        assert!(n > 0);
    }
}
