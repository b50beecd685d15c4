//! A child process a test starts and must never leave behind, and the recorder's status events
//! a test waits for, both bounded in time.

use std::process::{Child, Output};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Kills the child when dropped while it still runs, so a failing test never leaves it behind.
/// Take it out (`.0.take()`) to wait for its output.
pub struct Reap(pub Option<Child>);

impl Reap {
    /// Reaps `child`.
    pub fn new(child: Child) -> Self {
        Self(Some(child))
    }

    /// The child, while it is still held.
    pub fn child(&mut self) -> &mut Child {
        self.0.as_mut().expect("the child was taken")
    }

    /// Whether it has exited (and how), without waiting.
    pub fn exited(&mut self) -> Option<std::process::ExitStatus> {
        self.child().try_wait().expect("try_wait")
    }

    /// Its output, once it exits; fails the test if it still runs after `within`.
    pub fn output_within(mut self, within: Duration) -> Output {
        let deadline = Instant::now() + within;
        while self.exited().is_none() {
            assert!(
                Instant::now() < deadline,
                "the child still runs after {within:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let child = self.0.take().expect("the child was taken");
        child.wait_with_output().expect("wait_with_output")
    }
}

impl Drop for Reap {
    fn drop(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The next status event named `event` within `within` (others are skipped, but a `failed`
/// one fails the test with its text).
pub fn wait_status(
    rx: &mpsc::Receiver<serde_json::Value>,
    event: &str,
    within: Duration,
) -> serde_json::Value {
    let deadline = Instant::now() + within;
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .unwrap_or_else(|| panic!("no '{event}' status within {within:?}"));
        match rx.recv_timeout(left) {
            Ok(v) if v["event"] == event => return v,
            Ok(v) => assert_ne!(v["event"], "failed", "{v}"),
            Err(e) => panic!("no '{event}' status: {e}"),
        }
    }
}
