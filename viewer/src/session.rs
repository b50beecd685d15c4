//! A viewing session: [`ViewOptions`] → [`ViewOptions::open`] → [`Viewer`] → [`Viewer::show`]
//! per input → [`Viewer::finish`]. Each episode becomes one rerun recording (application
//! `scaledp`), so several inputs sit side by side in one viewer or one `.rrd` file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rerun::RecordingStream;
use scaledp_converter::ConvertOptions;
use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;

use crate::dataset::Dataset;
use crate::episode::Prediction;
use crate::error::{Error, Result};
use crate::input::{classify, directory_inputs, InputKind};
use crate::layout;
use crate::recording::{self, Collector};
use crate::sink::{Sink, Target};

/// How to show inputs. Defaults: every episode, images at their stored size, the rig stored in
/// the input (else detected), action chunks of 16 frames.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    max_width: Option<u32>,
    episodes: Vec<u64>,
    rig: Option<Rig>,
    chunk: usize,
    predictions: BTreeMap<u64, Prediction>,
    action_space: ActionSpace,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            max_width: None,
            episodes: Vec::new(),
            rig: None,
            chunk: 16,
            predictions: BTreeMap::new(),
            action_space: ActionSpace::Tcp,
        }
    }
}

/// What one episode showed.
#[derive(Debug, Clone, PartialEq)]
pub struct Shown {
    /// The recording's name in the viewer.
    pub name: String,
    /// What kind of input it came from.
    pub kind: InputKind,
    /// Frames (ticks of a recording, rows of a dataset episode) shown as state and action;
    /// 0 when the episode could not be aligned.
    pub frames: usize,
    /// Camera frames logged, per camera entity.
    pub images: BTreeMap<String, u64>,
    /// Problems met (undecodable messages, a cut file, why the converter would reject it).
    pub warnings: Vec<String>,
}

/// What a session wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Every episode shown, in order.
    pub shown: Vec<Shown>,
    /// The `.rrd` file written, with [`Target::Save`].
    pub saved: Option<PathBuf>,
}

impl ViewOptions {
    /// Default options.
    pub fn new() -> Self {
        Self::default()
    }
    /// Downsamples images wider than `px` (aspect kept).
    pub fn max_width(mut self, px: Option<u32>) -> Self {
        self.max_width = px.filter(|&p| p > 0);
        self
    }
    /// Shows only these episodes: a dataset's `episode_index`, or the position of an input in
    /// a directory (sorted, so `episode_000003.mcap` is 3 when none is missing). Empty: all.
    pub fn episodes(mut self, episodes: Vec<u64>) -> Self {
        self.episodes = episodes;
        self
    }
    /// Maps topics with this rig instead of the stored or detected one.
    pub fn rig(mut self, rig: Option<Rig>) -> Self {
        self.rig = rig;
        self
    }
    /// A policy's predicted chunks for dataset episode `episode` (its `episode_index`), drawn
    /// per arm beside the recorded chunk.
    pub fn prediction(mut self, episode: u64, prediction: Prediction) -> Self {
        self.predictions.insert(episode, prediction);
        self
    }

    /// The space recordings are shown in, as `scaledp convert --action` would convert them
    /// (default TCP poses; a dataset is shown in its own).
    pub fn action_space(mut self, space: ActionSpace) -> Self {
        self.action_space = space;
        self
    }

    /// Actions drawn ahead of each frame (the policy's action chunk).
    pub fn chunk(mut self, frames: usize) -> Self {
        self.chunk = frames;
        self
    }

    /// Checks every location (kind, episode range) before opening `target`, so a bad input
    /// fails before a viewer is spawned or a file is created.
    pub fn check(&self, locations: &[String]) -> Result<()> {
        for l in locations {
            self.episodes_of(l)?;
        }
        Ok(())
    }

    /// Opens the target (spawns or reaches the viewer, or starts the file).
    pub fn open(self, target: &Target) -> Result<Viewer> {
        Ok(Viewer {
            sink: Some(Sink::open(target)?),
            opts: self,
            streams: Vec::new(),
            shown: Vec::new(),
        })
    }

    /// The episodes of `location` to show: (kind, input path or dataset, episode index).
    fn episodes_of(&self, location: &str) -> Result<Vec<(InputKind, String, Option<u64>)>> {
        let kind = classify(location)?;
        let out_of_range = |n: u64, available: String| Error::NoSuchEpisode {
            location: location.to_string(),
            episode: n,
            available,
        };
        match kind {
            InputKind::Dataset => {
                let ds = Dataset::open(location)?;
                let have: Vec<u64> = ds.episodes.iter().map(|e| e.index).collect();
                let pick = if self.episodes.is_empty() {
                    have.clone()
                } else {
                    self.episodes.clone()
                };
                for &n in &pick {
                    if !have.contains(&n) {
                        return Err(out_of_range(n, describe(&have)));
                    }
                }
                Ok(pick
                    .into_iter()
                    .map(|n| (kind, location.to_string(), Some(n)))
                    .collect())
            }
            InputKind::Directory => {
                let inputs = directory_inputs(Path::new(location))?;
                let mut out = Vec::new();
                let all: Vec<u64> = (0..inputs.len() as u64).collect();
                let pick = if self.episodes.is_empty() {
                    all.clone()
                } else {
                    self.episodes.clone()
                };
                for n in pick {
                    let p = inputs
                        .get(n as usize)
                        .ok_or_else(|| out_of_range(n, describe(&all)))?;
                    let k = classify(&p.display().to_string())?;
                    out.push((k, p.display().to_string(), None));
                }
                Ok(out)
            }
            _ => {
                if let Some(&n) = self.episodes.iter().find(|&&n| n != 0) {
                    return Err(out_of_range(n, "a single recording is episode 0".into()));
                }
                Ok(vec![(kind, location.to_string(), None)])
            }
        }
    }
}

/// `episodes 0..=4`, or the list when not contiguous.
fn describe(have: &[u64]) -> String {
    match (have.first(), have.last()) {
        (None, _) | (_, None) => "it has no episodes".into(),
        (Some(a), Some(b)) if (b - a) as usize + 1 == have.len() => format!("episodes {a}..={b}"),
        _ => format!("episodes {have:?}"),
    }
}

/// An open session.
pub struct Viewer {
    sink: Option<Sink>,
    opts: ViewOptions,
    streams: Vec<RecordingStream>,
    shown: Vec<Shown>,
}

impl Viewer {
    /// Shows every selected episode of `location` (a path or `s3://` URL); returns them.
    pub fn show(&mut self, location: &str) -> Result<Vec<Shown>> {
        let mut out = Vec::new();
        for (kind, input, episode) in self.opts.episodes_of(location)? {
            let shown = match kind {
                InputKind::Dataset => self.show_dataset(&input, episode.unwrap_or(0))?,
                _ => self.show_recording(kind, Path::new(&input))?,
            };
            self.shown.push(shown.clone());
            out.push(shown);
        }
        Ok(out)
    }

    fn stream(&mut self, id: &str, name: &str) -> Result<RecordingStream> {
        let sink = self
            .sink
            .as_ref()
            .ok_or_else(|| Error::Rerun("the session is finished".into()))?;
        let rec = sink.stream(id, name)?;
        rec.set_log_tick_enabled(false);
        rec.set_log_time_enabled(false);
        self.streams.push(rec.clone());
        Ok(rec)
    }

    fn show_dataset(&mut self, location: &str, episode: u64) -> Result<Shown> {
        let ds = Dataset::open(location)?;
        let ep = ds
            .episodes
            .iter()
            .find(|e| e.index == episode)
            .cloned()
            .ok_or_else(|| Error::NoSuchEpisode {
                location: location.into(),
                episode,
                available: describe(&ds.episodes.iter().map(|e| e.index).collect::<Vec<_>>()),
            })?;
        let name = format!("{}/episode_{episode:06}", ds.name());
        let rec = self.stream(&format!("{}#{episode}", ds.location()), &name)?;
        layout::blueprint(&ds.shape(self.opts.rig.as_ref()))
            .send(
                &rec,
                rerun::blueprint::BlueprintActivation {
                    make_active: true,
                    make_default: true,
                },
            )
            .map_err(Error::rerun)?;
        let (frames, images, warnings) = ds.show_episode(
            &rec,
            &ep,
            self.opts.rig.as_ref(),
            self.opts.max_width,
            self.opts.chunk,
            self.opts.predictions.get(&episode),
        )?;
        Ok(Shown {
            name,
            kind: InputKind::Dataset,
            frames,
            images,
            warnings,
        })
    }

    fn show_recording(&mut self, kind: InputKind, path: &Path) -> Result<Shown> {
        let name = path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let id = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        let rec = self.stream(&id.display().to_string(), &name)?;
        let (collected, rig) = match kind {
            InputKind::Mcap => recording::stream_mcap(
                path,
                Collector::new(&rec, self.opts.max_width, self.opts.rig.clone()),
            )?,
            _ => {
                // Bags are read whole: detect the rig first so entities get the rig's names.
                let bag = scaledp_converter::read_input(path)?;
                let rig = self.opts.rig.clone().or_else(|| detect(path, &bag));
                recording::replay(&bag, Collector::new(&rec, self.opts.max_width, rig))?
            }
        };
        let mut warnings = recording::warnings(&collected);
        let mut convert = viewing_options().action_space(self.opts.action_space);
        if let Some(r) = self.opts.rig.clone().or(rig) {
            convert = convert.rig(r);
        }
        let shown = crate::ticks::show_episode(&rec, path, &collected, &convert, self.opts.chunk)?;
        warnings.extend(shown.warnings);
        recording::log_warnings(&rec, &warnings, collected.first_ns())?;
        Ok(Shown {
            name,
            kind,
            frames: shown.frames,
            images: collected.frames_logged,
            warnings,
        })
    }

    /// Flushes everything; renames the `.rrd` into place. Nothing is left under the output
    /// name when this fails.
    pub fn finish(mut self) -> Result<Summary> {
        let sink = self
            .sink
            .take()
            .ok_or_else(|| Error::Rerun("the session is finished".into()))?;
        let saved = sink.finish(std::mem::take(&mut self.streams))?;
        Ok(Summary {
            shown: std::mem::take(&mut self.shown),
            saved,
        })
    }
}

impl Drop for Viewer {
    /// A session dropped without [`Viewer::finish`] (an error on the way) removes its partial
    /// file.
    fn drop(&mut self) {
        if let Some(sink) = self.sink.take() {
            sink.abandon(std::mem::take(&mut self.streams));
        }
    }
}

/// The converter's defaults, except that an episode without a task or with many invalid ticks
/// is still shown (the viewer reports what the converter would reject instead), and depth is
/// left out of its state and action view (depth frames are shown as recorded).
fn viewing_options() -> ConvertOptions {
    ConvertOptions::default()
        .task("")
        .max_invalid_fraction(1.0)
        .depth(false)
}

/// The rig the converter would detect in a bag (for entity names), if any.
fn detect(path: &Path, bag: &scaledp_converter::Recording) -> Option<Rig> {
    let opts = viewing_options();
    let stamps = crate::ticks::NoPixels::from_recording(bag);
    scaledp_converter::convert(path, bag, &stamps, &opts)
        .ok()
        .map(|e| e.rig)
}

/// Shows `locations` at `target` with `opts` in one call: checks every input first, then
/// writes, then finishes (see [`Viewer`]).
pub fn view(locations: &[String], opts: ViewOptions, target: &Target) -> Result<Summary> {
    opts.check(locations)?;
    let mut viewer = opts.open(target)?;
    for l in locations {
        viewer.show(l)?;
    }
    viewer.finish()
}
