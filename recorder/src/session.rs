//! A recording session: Zenoh subscribers → a byte-bounded queue → one writer thread → files.
//!
//! Zenoh callbacks never block: they stamp the receive time, count, and hand the payload (a
//! reference-counted buffer, not a copy) to the queue, or count a drop when the queue already
//! holds `queue_bytes`. Commands travel through the same queue, so an episode holds exactly the
//! messages received between its start and stop. Latched topics are queued while no episode is
//! open too: the writer keeps their latest messages for the start of every episode.

use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::thread::JoinHandle;

use crossbeam_channel::Receiver;
use zenoh::Wait;

use crate::channels::Channel;
use crate::control::Command;
use crate::error::{Error, Result};
use crate::intake::Control;
use crate::links::LinkWatch;
use crate::liveness::Liveness;
use crate::options::RecorderOptions;
use crate::report::{Event, Status, TopicStatus};
use crate::state::Shared;
use crate::subscribe::{self, Sub};
use crate::writer::WriterThread;

impl RecorderOptions {
    /// Opens a Zenoh session with `config`, subscribes to every topic of the rig (bridge and
    /// rmw_zenoh keys; latched topics also through the publishers' caches) and to the control
    /// key, and starts the writer thread. No episode is open until a [`crate::Command::Start`].
    pub fn start(self, config: zenoh::Config) -> Result<Recorder> {
        std::fs::create_dir_all(&self.out_dir).map_err(Error::io(&self.out_dir))?;
        let topics = self.rig.topics();
        let mut search = self.msg_search.clone();
        let channels: Vec<Channel> = topics
            .iter()
            .map(|t| Channel::resolve(t.clone(), &mut search))
            .collect();
        let session = crate::net::open(config)?;
        let shared = Arc::new(Shared::new(&topics, self.queue_bytes, &self.task));
        let (tx, rx) = crossbeam_channel::unbounded();
        let control = Control::new(tx, shared.clone());
        let ns = self.bridge_namespace.clone();
        let mut subscribers = subscribe::topics(&session, &control, &topics, &ns)?;
        for p in &self.patterns {
            subscribers.extend(subscribe::pattern(&session, &control, p, &ns)?);
        }
        if !self.patterns.is_empty() {
            subscribers.push(subscribe::bridge_types(&session, &shared)?);
        }
        subscribers.push(subscribe::control(
            &session,
            &control,
            &self.control_prefix,
        )?);
        let (events_tx, events) = crossbeam_channel::unbounded();
        let writer = WriterThread::new(
            self,
            channels,
            search,
            shared.clone(),
            events_tx,
            session.clone(),
        );
        let handle = std::thread::Builder::new()
            .name("scaledp-writer".into())
            .spawn(move || writer.run(rx))
            .map_err(Error::io("writer thread"))?;
        // The caches of zenoh-bridge-ros2dds up to 1.5.0 are queried now and whenever a link
        // comes (back) up: a bridge restarted meanwhile serves its cache again.
        let latched = subscribe::latched_keys(&topics, &ns);
        let (s, c) = (session.clone(), control.clone());
        let query = move || subscribe::query_bridge_caches(&s, &c, &latched);
        query();
        let links = LinkWatch::start(session.clone(), shared.clone(), Box::new(query))?;
        Ok(Recorder::new(
            session,
            subscribers,
            control,
            shared,
            events,
            handle,
            links,
        ))
    }
}

/// A running recording session.
pub struct Recorder {
    session: zenoh::Session,
    subscribers: Vec<Sub>,
    control: Control,
    shared: Arc<Shared>,
    events: Receiver<Event>,
    writer: Option<JoinHandle<()>>,
    links: Option<LinkWatch>,
}

impl Recorder {
    pub(crate) fn new(
        session: zenoh::Session,
        subscribers: Vec<Sub>,
        control: Control,
        shared: Arc<Shared>,
        events: Receiver<Event>,
        writer: JoinHandle<()>,
        links: LinkWatch,
    ) -> Self {
        Self {
            session,
            subscribers,
            control,
            shared,
            events,
            writer: Some(writer),
            links: Some(links),
        }
    }
    /// Zenoh peers and routers the session is linked to (counted every 250 ms): 0 while the
    /// bridge or router is unreachable.
    pub fn zenoh_links(&self) -> usize {
        self.shared.links.load(Relaxed)
    }
    /// Times every link was lost since the session opened.
    pub fn link_outages(&self) -> u64 {
        self.shared.outage_figures().0
    }
    /// A handle for sending commands from other threads.
    pub fn control(&self) -> Control {
        self.control.clone()
    }
    /// Sends a command.
    pub fn send(&self, cmd: Command) {
        self.control.send(cmd);
    }
    /// Episode events, in order.
    pub fn events(&self) -> &Receiver<Event> {
        &self.events
    }
    /// The Zenoh session (for publishing status or bench loads on the same link).
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }
    /// Live figures.
    pub fn status(&self) -> Status {
        let topics = self
            .shared
            .topics
            .read()
            .map(|topics| {
                topics
                    .iter()
                    .map(|e| TopicStatus {
                        topic: e.spec.topic.clone(),
                        received: e.counters.received.load(Relaxed),
                        bytes: e.counters.bytes.load(Relaxed),
                        dropped: e.counters.dropped.load(Relaxed),
                        upstream_gaps: e.counters.upstream_gaps.load(Relaxed),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let episode = self.shared.active.lock().ok().and_then(|a| *a);
        Status {
            episode,
            topics,
            queued_bytes: self.shared.queued_bytes.load(Relaxed),
            held: self.shared.held.lock().ok().and_then(|h| *h),
            task: self.shared.task(),
            disk: self.shared.disk.lock().ok().and_then(|d| d.clone()),
        }
    }
    /// Whether the rig's topics are live at their rates now (what a start checks with
    /// [`RecorderOptions::check_topics`]).
    pub fn liveness(&self) -> Liveness {
        self.shared.liveness()
    }
    /// True while the writer thread runs (it stops after `quit`).
    pub fn is_running(&self) -> bool {
        self.writer.as_ref().is_some_and(|h| !h.is_finished())
    }

    /// Finishes an open episode as `unlabeled`, stops the writer and closes the session.
    pub fn finish(mut self) -> Result<()> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<()> {
        if let Some(links) = self.links.take() {
            links.stop();
        }
        for s in self.subscribers.drain(..) {
            s.undeclare();
        }
        self.control.send(Command::Quit);
        if let Some(h) = self.writer.take() {
            h.join().map_err(|_| Error::Stopped)?;
        }
        self.session
            .close()
            .wait()
            .map_err(|e| Error::Zenoh(e.to_string()))
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.writer.is_some() {
            let _ = self.shutdown();
        }
    }
}
