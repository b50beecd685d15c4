//! Watches the session's links (to the bridge, a router, peers): says when the last one is lost
//! and when one is back, counts the outages and their length for the episodes' metadata, and
//! asks the publishers' caches again when a link comes up. Zenoh reconnects to its `connect`
//! endpoints by itself, but what is published meanwhile never arrives, and an operator should
//! know.

use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use zenoh::Wait;

use crate::error::{Error, Result};
use crate::state::{now_ns, Shared};

pub(crate) struct LinkWatch {
    stop: Arc<AtomicBool>,
    handle: JoinHandle<()>,
}

impl LinkWatch {
    /// How often the links are counted.
    const EVERY: Duration = Duration::from_millis(250);

    /// Starts watching; `on_up` runs whenever a link comes up (the first time included).
    pub(crate) fn start(
        session: zenoh::Session,
        shared: Arc<Shared>,
        on_up: Box<dyn Fn() + Send>,
    ) -> Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let handle = std::thread::Builder::new()
            .name("scaledp-links".into())
            .spawn(move || {
                // None until the first link: a recorder started before the bridge is not "down".
                let mut up: Option<bool> = None;
                while !stopped.load(Relaxed) {
                    let info = session.info();
                    let n = info.routers_zid().wait().count() + info.peers_zid().wait().count();
                    shared.links.store(n, Relaxed);
                    match (up, n > 0) {
                        (Some(true), false) => {
                            shared.outages.fetch_add(1, Relaxed);
                            shared.down_since_ns.store(now_ns(), Relaxed);
                            tracing::warn!(
                                "zenoh: every link is down (bridge or router gone?): \
                                 reconnecting; messages published meanwhile are lost"
                            );
                        }
                        (Some(false), true) => {
                            let since = shared.down_since_ns.swap(0, Relaxed);
                            let lost_ns = now_ns().saturating_sub(since);
                            shared.outage_ns.fetch_add(lost_ns, Relaxed);
                            tracing::warn!(
                                "zenoh: link back ({n} peers and routers) after {:.1} s",
                                lost_ns as f64 * 1e-9
                            );
                            on_up();
                        }
                        (None, true) => on_up(),
                        _ => {}
                    }
                    if up.is_some() || n > 0 {
                        up = Some(n > 0);
                    }
                    std::thread::sleep(Self::EVERY);
                }
            })
            .map_err(Error::io("link watch thread"))?;
        Ok(Self { stop, handle })
    }

    pub(crate) fn stop(self) {
        self.stop.store(true, Relaxed);
        let _ = self.handle.join();
    }
}
