//! `scaledp eval --recordings DIR`: each rollout kept as an MCAP episode, written with the
//! recorder's own episode writer in the layout `scaledp record` writes (every topic of the
//! rig, command topics included, `scaledp.episode` metadata with the rig, the task and the
//! scorer's label), so failures can be converted, inspected and added to the data.

use std::path::{Path, PathBuf};

use scaledp_recorder::{episode_file_name, EpisodeOptions, EpisodeWriter};
use scaledp_schema::rig::TopicSpec;
use scaledp_schema::{EpisodeMetadata, Label, Rig};

use crate::error::{Error, Result};

/// The task in words, as `scaledp collect` states it: the cube cell's, or a simulator's task
/// by name (`metaworld assembly`).
pub fn task_text(rig: &Rig) -> String {
    if let Some(sim) = &rig.simulator {
        return format!("{} {}", sim.bridge, sim.task);
    }
    if rig.arms.len() > 1 {
        "put the red cube on the green square and the blue cube on the yellow square".into()
    } else {
        "put the red cube on the green square".into()
    }
}

/// One rollout being written.
pub(crate) struct Rollout {
    w: EpisodeWriter,
    topics: Vec<TopicSpec>,
    meta: EpisodeMetadata,
    path: PathBuf,
}

impl Rollout {
    /// `dir/episode_<index>.mcap` for `rig`, seed `seed`, driven by `checkpoint`, starting at
    /// `start_ns`.
    pub(crate) fn create(
        dir: &Path,
        index: u64,
        rig: &Rig,
        seed: u64,
        checkpoint: &str,
        start_ns: u64,
    ) -> Result<Self> {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let path = dir.join(episode_file_name(index));
        let topics = rig.topics();
        let meta = EpisodeMetadata {
            episode_index: Some(index),
            task: task_text(rig),
            operator: format!("policy {checkpoint}"),
            rig_name: rig.name.clone(),
            rig_toml: toml::to_string(rig).ok(),
            start_time_ns: Some(start_ns),
            synthetic: Some(format!("scaledp eval, seed {seed}")),
            ..EpisodeMetadata::default()
        };
        let w = EpisodeOptions::new().create(&path, &topics, meta.start_record())?;
        Ok(Rollout {
            w,
            topics,
            meta,
            path,
        })
    }

    /// One message on `topic` (ignored if the rig has no such topic), stamped and logged at
    /// `stamp_ns` (simulated time has no transport delay).
    pub(crate) fn write(&mut self, topic: &str, stamp_ns: u64, data: &[u8]) -> Result<()> {
        if let Some(i) = self.topics.iter().position(|t| t.topic == topic) {
            self.w.write(i, stamp_ns, stamp_ns, data)?;
        }
        Ok(())
    }

    /// Labels the episode by the scorer and closes it; returns its path.
    pub(crate) fn finish(self, success: bool, end_ns: u64, duration_s: f64) -> Result<PathBuf> {
        let meta = EpisodeMetadata {
            end_time_ns: Some(end_ns),
            duration_s: Some(duration_s),
            label: Some(if success {
                Label::Success
            } else {
                Label::Failure
            }),
            message_counts: self
                .topics
                .iter()
                .zip(self.w.message_counts())
                .map(|(t, n)| (t.topic.clone(), *n))
                .collect(),
            ..self.meta
        };
        self.w.finish(meta.end_record(), None)?;
        Ok(self.path)
    }
}
