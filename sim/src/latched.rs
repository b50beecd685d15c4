//! A latched (transient-local) publisher, as a late joiner finds one behind Zenoh: tf2's
//! `/tf_static`, published once and served from a cache to whoever subscribes later.
//!
//! - [`LatchedCache::Advanced`]: a zenoh-ext `AdvancedPublisher` with a one-sample cache that
//!   announces itself (what rmw_zenoh and zenoh-bridge-ros2dds from 1.5.1 declare).
//! - [`LatchedCache::BridgeQueryable`]: a plain publisher and a queryable at
//!   `<key>/@ros2_pub_cache/<zid>` replying with the latest sample under its own key (the
//!   `PublicationCache` of zenoh-bridge-ros2dds up to 1.5.0).

use std::sync::{Arc, Mutex};

use scaledp_recorder::keys::bridge_cache_queryable;
use zenoh::bytes::ZBytes;
use zenoh::query::Query;
use zenoh::Wait;
use zenoh_ext::{AdvancedPublisher, AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::{Error, Result};

/// How a latched topic is served to subscribers that join after it was published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LatchedCache {
    /// A zenoh-ext AdvancedPublisher's cache (rmw_zenoh; zenoh-bridge-ros2dds ≥ 1.5.1).
    Advanced,
    /// A `@ros2_pub_cache` queryable (zenoh-bridge-ros2dds ≤ 1.5.0).
    BridgeQueryable,
}

/// The latest sample a bridge-style cache serves: payload and attachment.
type Kept = Arc<Mutex<Option<(Vec<u8>, Option<ZBytes>)>>>;

enum Inner {
    Advanced(AdvancedPublisher<'static>),
    Queryable {
        publisher: zenoh::pubsub::Publisher<'static>,
        _queryable: zenoh::query::Queryable<()>,
        last: Kept,
    },
}

/// A publisher whose latest message late subscribers still get.
pub(crate) struct LatchedPublisher {
    key: String,
    inner: Inner,
}

impl LatchedPublisher {
    pub fn declare(session: &zenoh::Session, key: &str, cache: LatchedCache) -> Result<Self> {
        let zerr = |e: zenoh::Error| Error::Zenoh {
            key: key.to_string(),
            reason: e.to_string(),
        };
        let inner = match cache {
            LatchedCache::Advanced => {
                let declare = |sequenced: bool| {
                    let b = session.declare_publisher(key.to_string());
                    let b = if sequenced {
                        b.sample_miss_detection(MissDetectionConfig::default())
                    } else {
                        b.advanced()
                    };
                    b.cache(CacheConfig::default().max_samples(1))
                        .publisher_detection()
                        .wait()
                };
                // A cache orders its samples by timestamp; a session that does not stamp them
                // (a Zenoh config file without `timestamping`) numbers them instead.
                let publisher = declare(false).or_else(|_| declare(true)).map_err(zerr)?;
                Inner::Advanced(publisher)
            }
            LatchedCache::BridgeQueryable => {
                let last: Kept = Arc::default();
                let served = last.clone();
                let reply_key = key.to_string();
                let queryable = session
                    .declare_queryable(bridge_cache_queryable(key, &session.zid().to_string()))
                    .callback(move |q: Query| {
                        let latest = served.lock().ok().and_then(|l| l.clone());
                        if let Some((payload, att)) = latest {
                            let reply = q.reply(reply_key.as_str(), payload);
                            let reply = match att {
                                Some(a) => reply.attachment(a),
                                None => reply,
                            };
                            if let Err(e) = reply.wait() {
                                tracing::debug!("{reply_key}: cache reply: {e}");
                            }
                        }
                    })
                    .wait()
                    .map_err(zerr)?;
                let publisher = session
                    .declare_publisher(key.to_string())
                    .wait()
                    .map_err(zerr)?;
                Inner::Queryable {
                    publisher,
                    _queryable: queryable,
                    last,
                }
            }
        };
        Ok(Self {
            key: key.to_string(),
            inner,
        })
    }

    /// Publishes `payload` (with an rmw_zenoh attachment when given) and keeps it for late
    /// joiners.
    pub fn publish(&self, payload: Vec<u8>, attachment: Option<ZBytes>) {
        let sent = match &self.inner {
            Inner::Advanced(p) => {
                let put = p.put(payload);
                match attachment {
                    Some(a) => put.attachment(a).wait(),
                    None => put.wait(),
                }
            }
            Inner::Queryable {
                publisher, last, ..
            } => {
                if let Ok(mut l) = last.lock() {
                    *l = Some((payload.clone(), attachment.clone()));
                }
                let put = publisher.put(payload);
                match attachment {
                    Some(a) => put.attachment(a).wait(),
                    None => put.wait(),
                }
            }
        };
        if let Err(e) = sent {
            tracing::warn!("{}: {e}", self.key);
        }
    }
}
