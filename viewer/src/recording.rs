//! Recordings and bags: every message as it was recorded (each camera frame at its capture
//! stamp, each joint state), then what the converter would make of the episode (see
//! [`crate::episode`]). MCAP files stream in one forward read; rosbag2 and ROS 1 bags are read
//! whole by the converter's readers (their formats have no cheap forward read here).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use rerun::{RecordingStream, Scalars, SeriesLines, TextLog};
use scaledp_converter::{RawMessage, Recording, Serialization, TopicInfo};
use scaledp_schema::episode::{END_RECORD, START_RECORD};
use scaledp_schema::msg::JointState;
use scaledp_schema::rig::Rig;
use scaledp_schema::{EpisodeMetadata, RosMessage};

use crate::error::{Error, Result};
use crate::images::message_frame;
use crate::layout;
use crate::mcap_read;
use crate::sink::Backpressure;

/// Where a topic's messages go.
#[derive(Debug, Clone)]
enum Route {
    Camera(String),
    /// `/tf` (false) or `/tf_static` (true).
    Tf(bool),
    Arm(usize),
    Gripper(usize),
    Topic(String),
    Keep,
}

/// What was shown of the raw messages, and what the episode view needs afterwards.
#[derive(Debug, Default)]
pub(crate) struct Collected {
    /// Non-image messages and the first frame of each camera topic (for rig detection).
    pub recording: Recording,
    /// Per image topic: (header stamp or 0, log time) of every frame, in stored order.
    pub frame_stamps: BTreeMap<String, Vec<(u64, u64)>>,
    /// Per joint-state topic: the stamp of every message (header, else log time).
    pub joint_stamps: BTreeMap<String, Vec<u64>>,
    /// Frames logged per camera entity.
    pub frames_logged: BTreeMap<String, u64>,
    /// Joint-state messages logged.
    pub joint_messages: u64,
    /// tf transforms logged (`/tf`, `/tf_static`).
    pub transforms: u64,
    /// Per topic: messages that could not be decoded, and the first reason.
    pub undecodable: BTreeMap<String, (u64, String)>,
    /// Why reading stopped early, if it did.
    pub cut: Option<String>,
}

/// Logs messages as they arrive and keeps what the episode view needs.
pub(crate) struct Collector<'a> {
    rec: &'a RecordingStream,
    max_width: Option<u32>,
    rig: Option<Rig>,
    routes: HashMap<String, Route>,
    topics: BTreeMap<String, TopicInfo>,
    /// Per joint route: where each wanted joint sits in the last name list seen.
    index: HashMap<String, (Vec<String>, Vec<Option<usize>>)>,
    /// Keep messages and stamps for the episode view (not in a live session).
    keep: bool,
    pace: Backpressure,
    tf: crate::depth::TfTree,
    out: Collected,
}

impl<'a> Collector<'a> {
    /// A collector naming entities after `rig`'s cameras and arms when one is known.
    pub fn new(rec: &'a RecordingStream, max_width: Option<u32>, rig: Option<Rig>) -> Self {
        Self {
            rec,
            max_width,
            rig,
            routes: HashMap::new(),
            topics: BTreeMap::new(),
            index: HashMap::new(),
            keep: true,
            pace: Backpressure::default(),
            tf: crate::depth::TfTree::default(),
            out: Collected::default(),
        }
    }

    /// A collector that only logs (a live session keeps nothing).
    pub fn live(rec: &'a RecordingStream, max_width: Option<u32>, rig: Option<Rig>) -> Self {
        Self {
            keep: false,
            ..Self::new(rec, max_width, rig)
        }
    }

    /// A metadata record: the episode's rig names entities, if no message was routed yet.
    pub fn metadata(&mut self, name: &str, record: &BTreeMap<String, String>) {
        if name != START_RECORD && name != END_RECORD {
            return;
        }
        if self.rig.is_some() || !self.routes.is_empty() {
            return;
        }
        if let Some(text) = EpisodeMetadata::from_record(record)
            .ok()
            .and_then(|m| m.rig_toml)
        {
            self.rig = Rig::parse(&text, Path::new("episode metadata")).ok();
        }
    }

    fn route(&self, topic: &str, message_type: &str) -> Route {
        let is_image = matches!(
            message_type,
            "sensor_msgs/msg/Image" | "sensor_msgs/msg/CompressedImage"
        );
        if let Some(rig) = &self.rig {
            if let Some(c) = rig.cameras.iter().find(|c| c.topic == topic) {
                return Route::Camera(layout::camera(&c.name));
            }
            let depth_of = |c: &&scaledp_schema::rig::Camera| {
                c.depth.as_ref().is_some_and(|d| d.topic == topic)
            };
            if let Some(c) = rig.cameras.iter().find(depth_of) {
                return Route::Camera(layout::depth(&c.name));
            }
            for (i, a) in rig.arms.iter().enumerate() {
                if a.joint_state_topic == topic {
                    return Route::Arm(i);
                }
                if a.gripper.as_ref().is_some_and(|g| g.topic == topic) {
                    return Route::Gripper(i);
                }
            }
        }
        match message_type {
            _ if is_image => {
                Route::Camera(layout::camera(&topic.trim_matches('/').replace('/', "_")))
            }
            "sensor_msgs/msg/JointState" => Route::Topic(layout::topic(topic)),
            scaledp_schema::rig::TF_MESSAGE => Route::Tf(topic == "/tf_static"),
            _ => Route::Keep,
        }
    }

    fn failed(&mut self, topic: &str, reason: String) {
        let e = self
            .out
            .undecodable
            .entry(topic.to_string())
            .or_insert((0, reason));
        e.0 += 1;
    }

    /// One message, whatever its format.
    pub fn message(
        &mut self,
        topic: &str,
        message_type: &str,
        log_time_ns: u64,
        serialization: Serialization,
        data: &[u8],
    ) -> Result<()> {
        let info = self
            .topics
            .entry(topic.to_string())
            .or_insert_with(|| TopicInfo {
                topic: topic.to_string(),
                message_type: message_type.to_string(),
                count: Some(0),
            });
        info.count = info.count.map(|c| c + 1);
        let route = match self.routes.get(topic) {
            Some(r) => r.clone(),
            None => {
                let r = self.route(topic, message_type);
                self.routes.insert(topic.to_string(), r.clone());
                r
            }
        };
        let raw = || RawMessage {
            topic: topic.to_string(),
            message_type: message_type.to_string(),
            log_time_ns,
            data: data.to_vec(),
            serialization,
        };
        self.rec
            .set_timestamp_nanos_since_epoch(layout::RECEIVE_TIME, log_time_ns as i64);
        match route {
            Route::Camera(entity) => {
                let first = !self.out.frame_stamps.contains_key(topic);
                if first && self.keep {
                    self.out.recording.messages.push(raw());
                }
                let shown = message_frame(message_type, serialization, data, self.max_width);
                let stamp = shown.as_ref().map_or(0, |(s, _)| *s);
                if self.keep || first {
                    self.out
                        .frame_stamps
                        .entry(topic.to_string())
                        .or_default()
                        .push((stamp, log_time_ns));
                }
                match shown {
                    Ok((stamp, frame)) => {
                        let t = if stamp == 0 { log_time_ns } else { stamp };
                        self.rec
                            .set_timestamp_nanos_since_epoch(layout::CAPTURE_TIME, t as i64);
                        frame.log(self.rec, &entity).map_err(Error::rerun)?;
                        *self.out.frames_logged.entry(entity).or_default() += 1;
                        self.pace.logged(self.rec, data.len())?;
                    }
                    Err(reason) => self.failed(topic, reason),
                }
            }
            Route::Arm(_) | Route::Gripper(_) | Route::Topic(_) => {
                let decoded = match serialization {
                    Serialization::Cdr => JointState::from_cdr(data).map_err(|e| e.to_string()),
                    Serialization::Ros1 => scaledp_converter::ros1::decode::joint_state(data)
                        .map_err(|e| e.to_string()),
                };
                if self.keep {
                    self.out.recording.messages.push(raw());
                }
                match decoded {
                    Ok(js) => self.joint_state(topic, &route, log_time_ns, &js)?,
                    Err(reason) => self.failed(topic, reason),
                }
            }
            Route::Tf(latched) if serialization == Serialization::Cdr => {
                match self.tf.message(self.rec, data, latched) {
                    Ok(n) => self.out.transforms += n as u64,
                    Err(reason) => self.failed(topic, reason),
                }
            }
            Route::Tf(_) => self.failed(topic, "tf from ROS 1 bags is not shown".into()),
            Route::Keep if self.keep => self.out.recording.messages.push(raw()),
            Route::Keep => {}
        }
        Ok(())
    }

    fn joint_state(
        &mut self,
        topic: &str,
        route: &Route,
        log_ns: u64,
        js: &JointState,
    ) -> Result<()> {
        let stamp = match js.header.stamp.as_ns() {
            0 => log_ns,
            s => s,
        };
        if self.keep {
            self.out
                .joint_stamps
                .entry(topic.to_string())
                .or_default()
                .push(stamp);
        }
        let (entity, wanted): (String, Option<Vec<String>>) = match (route, &self.rig) {
            (Route::Arm(i), Some(rig)) => (
                layout::joints(&rig.arms[*i].name),
                Some(rig.arms[*i].joint_names.clone()),
            ),
            (Route::Gripper(i), Some(rig)) => (
                layout::gripper(&rig.arms[*i].name),
                rig.arms[*i].gripper.as_ref().map(|g| g.joint_names.clone()),
            ),
            (Route::Topic(e), _) => (e.clone(), None),
            _ => return Ok(()),
        };
        let names = wanted.unwrap_or_else(|| js.name.clone());
        let (seen, index) = self
            .index
            .entry(topic.to_string())
            .or_insert_with(|| (Vec::new(), Vec::new()));
        let first = seen.is_empty() && index.is_empty();
        if *seen != js.name || first {
            *index = names
                .iter()
                .map(|n| js.name.iter().position(|x| x == n))
                .collect();
            *seen = js.name.clone();
        }
        let q: Option<Vec<f64>> = index
            .iter()
            .map(|i| i.and_then(|i| js.position.get(i).copied()))
            .collect();
        let Some(q) = q else {
            self.failed(topic, format!("joints {names:?} not all in {:?}", js.name));
            return Ok(());
        };
        let r = Error::rerun;
        self.rec
            .set_timestamp_nanos_since_epoch(layout::CAPTURE_TIME, stamp as i64);
        if let (Route::Gripper(i), Some(rig)) = (route, &self.rig) {
            if first {
                self.rec
                    .log_static(
                        entity.as_str(),
                        &SeriesLines::new().with_names(["opening (m)"]),
                    )
                    .map_err(r)?;
            }
            if let Some(g) = &rig.arms[*i].gripper {
                self.rec
                    .log(entity.as_str(), &Scalars::new([g.model.width_m(&q)]))
                    .map_err(r)?;
            }
        } else {
            if first {
                self.rec
                    .log_static(
                        entity.as_str(),
                        &SeriesLines::new().with_names(names.iter().map(String::as_str)),
                    )
                    .map_err(r)?;
            }
            self.rec.log(entity.as_str(), &Scalars::new(q)).map_err(r)?;
        }
        self.out.joint_messages += 1;
        Ok(())
    }

    /// Everything collected; the recording's topics and metadata filled in.
    pub fn finish(mut self, metadata: BTreeMap<String, BTreeMap<String, String>>) -> Collected {
        self.out.recording.topics = self.topics.into_values().collect();
        self.out.recording.metadata = metadata;
        self.out.recording.messages.sort_by_key(|m| m.log_time_ns);
        self.out
    }
}

struct Visit<'c, 'a>(&'c mut Collector<'a>);

impl mcap_read::Visitor for Visit<'_, '_> {
    fn metadata(&mut self, name: &str, record: &BTreeMap<String, String>) -> Result<()> {
        self.0.metadata(name, record);
        Ok(())
    }
    fn message(&mut self, m: mcap_read::Message<'_>) -> Result<()> {
        self.0.message(
            m.topic,
            m.message_type,
            m.log_time_ns,
            Serialization::Cdr,
            m.data,
        )
    }
}

/// Streams an MCAP file into `collector`.
pub(crate) fn stream_mcap(
    path: &Path,
    mut collector: Collector<'_>,
) -> Result<(Collected, Option<Rig>)> {
    let ending = mcap_read::read(path, &mut Visit(&mut collector))?;
    let rig = collector.rig.clone();
    let mut out = collector.finish(ending.metadata);
    out.cut = ending.cut;
    if ending.not_cdr > 0 {
        out.undecodable.insert(
            "(channels not cdr)".into(),
            (ending.not_cdr, "only cdr messages are shown".into()),
        );
    }
    Ok((out, rig))
}

/// Logs an in-memory recording (a bag) through `collector`.
pub(crate) fn replay(
    rec: &Recording,
    mut collector: Collector<'_>,
) -> Result<(Collected, Option<Rig>)> {
    for m in &rec.messages {
        collector.message(
            &m.topic,
            &m.message_type,
            m.log_time_ns,
            m.serialization,
            &m.data,
        )?;
    }
    let rig = collector.rig.clone();
    Ok((collector.finish(rec.metadata.clone()), rig))
}

/// One line per problem met while reading, for the text log.
pub(crate) fn warnings(c: &Collected) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(cut) = &c.cut {
        out.push(format!(
            "the file is incomplete: {cut}; everything before is shown"
        ));
    }
    for (topic, (n, reason)) in &c.undecodable {
        out.push(format!("{topic}: {n} messages not shown ({reason})"));
    }
    out
}

impl Collected {
    /// The earliest capture stamp of any frame (ns), 0 without frames.
    pub fn first_ns(&self) -> u64 {
        self.frame_stamps
            .values()
            .filter_map(|s| s.iter().map(|&(h, l)| if h == 0 { l } else { h }).min())
            .min()
            .unwrap_or(0)
    }
}

/// Logs `lines` as warnings in the text log at capture time `at_ns`.
pub(crate) fn log_warnings(rec: &RecordingStream, lines: &[String], at_ns: u64) -> Result<()> {
    rec.reset_time();
    rec.set_timestamp_nanos_since_epoch(layout::CAPTURE_TIME, at_ns as i64);
    for l in lines {
        rec.log(
            layout::LOG,
            &TextLog::new(l.as_str()).with_level(rerun::TextLogLevel::WARN),
        )
        .map_err(Error::rerun)?;
    }
    Ok(())
}
