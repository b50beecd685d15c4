//! The session's Zenoh subscriptions: every rig topic under both key styles, latched topics
//! through their publishers' caches as well, the `--topic` patterns, the control key, and the
//! bridge's announcements of its topics' types.
//!
//! How a late joiner gets a transient-local ("latched") publication such as `/tf_static`:
//! - rmw_zenoh (0.2.2 and later, Jazzy on) and zenoh-bridge-ros2dds from 1.5.1 publish it
//!   with a zenoh-ext `AdvancedPublisher` holding a cache and announcing itself; an
//!   `AdvancedSubscriber` with history queries those caches when it starts and whenever such a
//!   publisher appears later (`detect_late_publishers`).
//! - zenoh-bridge-ros2dds up to 1.5.0 serves it from a `PublicationCache` queryable at
//!   `<key>/@ros2_pub_cache/<bridge zid>`, replying with the publication's own key: the
//!   recorder queries `<key>/@ros2_pub_cache/*` accepting any reply key, when it starts and
//!   whenever a link comes back.

use std::sync::Arc;
use std::time::Duration;

use scaledp_schema::rig::TopicSpec;
use zenoh::query::{ConsolidationMode, QueryTarget, Reply, ReplyKeyExpr};
use zenoh::sample::Sample;
use zenoh::Wait;
use zenoh_ext::{AdvancedSubscriber, AdvancedSubscriberBuilderExt, HistoryConfig};

use crate::control::Command;
use crate::error::{Error, Result};
use crate::intake::Control;
use crate::keys::{
    bridge_cache_selector, bridge_key, parse_rmw_key, rmw_key_expr, topic_from_bridge_key,
};
use crate::patterns::TopicPattern;
use crate::state::Shared;

/// How long a query of the bridges' caches waits for replies.
const CACHE_QUERY_TIMEOUT: Duration = Duration::from_secs(5);

/// A subscription of either kind.
pub(crate) enum Sub {
    Plain(zenoh::pubsub::Subscriber<()>),
    Advanced(AdvancedSubscriber<()>),
}

impl Sub {
    pub(crate) fn undeclare(self) {
        match self {
            Self::Plain(s) => drop(s.undeclare().wait()),
            Self::Advanced(s) => drop(s.undeclare().wait()),
        }
    }
}

fn zerr(key: &str) -> impl Fn(zenoh::Error) -> Error + '_ {
    move |e| Error::Zenoh(format!("{key}: {e}"))
}

/// Every rig topic, as zenoh-bridge-ros2dds and as rmw_zenoh publish it.
pub(crate) fn topics(
    session: &zenoh::Session,
    control: &Control,
    topics: &[TopicSpec],
    namespace: &str,
) -> Result<Vec<Sub>> {
    let mut out = Vec::new();
    for (i, t) in topics.iter().enumerate() {
        let counters = control
            .shared
            .counters_of(i)
            .ok_or_else(|| Error::Zenoh(format!("{}: no counters", t.topic)))?;
        for key in [
            bridge_key(namespace, &t.topic),
            rmw_key_expr(&t.topic, &t.message_type),
        ] {
            let (c, counters) = (control.clone(), counters.clone());
            let latched = t.latched;
            let callback = move |s: Sample| c.on_sample(i, &counters, latched, &s);
            let sub = if latched {
                let history = HistoryConfig::default().detect_late_publishers();
                Sub::Advanced(
                    session
                        .declare_subscriber(&key)
                        .history(history)
                        .callback(callback)
                        .wait()
                        .map_err(zerr(&key))?,
                )
            } else {
                Sub::Plain(
                    session
                        .declare_subscriber(&key)
                        .callback(callback)
                        .wait()
                        .map_err(zerr(&key))?,
                )
            };
            out.push(sub);
        }
    }
    Ok(out)
}

/// The topics a `--topic` pattern matches, under both key styles: over rmw_zenoh the type is
/// the key's, over the bridge the pattern's or the one the bridge announces.
pub(crate) fn pattern(
    session: &zenoh::Session,
    control: &Control,
    p: &TopicPattern,
    namespace: &str,
) -> Result<Vec<Sub>> {
    let mut out = Vec::new();
    let key = p.bridge_key_expr(namespace);
    let (c, pat, ns) = (control.clone(), p.clone(), namespace.to_string());
    let sub = session
        .declare_subscriber(&key)
        .callback(move |s: Sample| {
            let key = s.key_expr().as_str();
            let Some(topic) = topic_from_bridge_key(&ns, key) else {
                return;
            };
            if !pat.matches(&topic) {
                return;
            }
            let announced = c
                .shared
                .bridge_types
                .lock()
                .ok()
                .and_then(|m| m.get(key).cloned());
            let ty = pat.message_type().map(str::to_owned).or(announced);
            c.on_found(&topic, ty.as_deref(), &s);
        })
        .wait()
        .map_err(zerr(&key))?;
    out.push(Sub::Plain(sub));
    let key = p.rmw_key_expr();
    let (c, pat) = (control.clone(), p.clone());
    let sub = session
        .declare_subscriber(&key)
        .callback(move |s: Sample| {
            if let Some((topic, ty)) = parse_rmw_key(s.key_expr().as_str()) {
                if pat.matches(&topic) {
                    c.on_found(&topic, Some(&ty), &s);
                }
            }
        })
        .wait()
        .map_err(zerr(&key))?;
    out.push(Sub::Plain(sub));
    Ok(out)
}

/// Learns the type of every topic zenoh-bridge-ros2dds routes from its liveliness tokens
/// (`@/<zid>/@ros2_lv/MP/<key>/<type>/<qos>`, `/` written `§`).
pub(crate) fn bridge_types(session: &zenoh::Session, shared: &Arc<Shared>) -> Result<Sub> {
    let key = "@/*/@ros2_lv/MP/**";
    let shared = shared.clone();
    let sub = session
        .liveliness()
        .declare_subscriber(key)
        .history(true)
        .callback(move |s: Sample| {
            let parts: Vec<&str> = s.key_expr().as_str().split('/').collect();
            if let [_, _, _, "MP", ke, ty, ..] = parts.as_slice() {
                let (ke, ty) = (ke.replace('§', "/"), ty.replace('§', "/"));
                if let Ok(mut m) = shared.bridge_types.lock() {
                    m.insert(ke, ty);
                }
            }
        })
        .wait()
        .map_err(zerr(key))?;
    Ok(Sub::Plain(sub))
}

/// The control key: commands as words (`start`, `stop`, `success`, …).
pub(crate) fn control(session: &zenoh::Session, control: &Control, prefix: &str) -> Result<Sub> {
    let key = format!("{prefix}/control");
    let c = control.clone();
    let sub = session
        .declare_subscriber(&key)
        .callback(move |s: Sample| {
            let text = String::from_utf8_lossy(&s.payload().to_bytes()).into_owned();
            match text.parse::<Command>() {
                Ok(cmd) => {
                    tracing::info!(command = ?cmd, "control over zenoh");
                    c.send(cmd);
                }
                Err(e) => tracing::warn!("{}: {e}", s.key_expr()),
            }
        })
        .wait()
        .map_err(zerr(&key))?;
    Ok(Sub::Plain(sub))
}

/// (topic number, bridge key) of every latched rig topic.
pub(crate) fn latched_keys(topics: &[TopicSpec], namespace: &str) -> Vec<(usize, String)> {
    topics
        .iter()
        .enumerate()
        .filter(|(_, t)| t.latched)
        .map(|(i, t)| (i, bridge_key(namespace, &t.topic)))
        .collect()
}

/// Asks every zenoh-bridge-ros2dds (up to 1.5.0) for what its cache holds of each latched
/// topic; the replies arrive as the topic's samples. Returns at once.
pub(crate) fn query_bridge_caches(
    session: &zenoh::Session,
    control: &Control,
    keys: &[(usize, String)],
) {
    for (i, key) in keys {
        let Some(counters) = control.shared.counters_of(*i) else {
            continue;
        };
        let (c, i) = (control.clone(), *i);
        let selector = bridge_cache_selector(key);
        let asked = session
            .get(&selector)
            .accept_replies(ReplyKeyExpr::Any)
            .consolidation(ConsolidationMode::None)
            .target(QueryTarget::All)
            .timeout(CACHE_QUERY_TIMEOUT)
            .callback(move |r: Reply| {
                if let Ok(s) = r.result() {
                    c.on_sample(i, &counters, true, s);
                }
            })
            .wait();
        if let Err(e) = asked {
            tracing::debug!("{selector}: {e}");
        }
    }
}
