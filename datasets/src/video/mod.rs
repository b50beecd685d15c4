//! Video features (LeRobot v3.0): frames in MP4 files under `videos/`, many episodes one after
//! another in a file. A frame is the one shown nearest to `from_timestamp + timestamp` (its
//! episode's start in the file plus the data row's `timestamp`), refused unless it is closer
//! than the tolerance (LeRobot's rule: `tolerance_s`, 1e-4 s by default). Reading a window
//! reads from the keyframe before its first frame to its last frame, nothing else; decoding
//! goes through the bounded [`cache::DecoderCache`]; pictures are converted to RGB as ffmpeg
//! converts them for LeRobot (`scaledp_codec::Yuv420`), resized bilinearly when another size is asked for.
//! A file's index is read once, on first use; a file that cannot be used fails the samples that
//! need it, each with one line naming the file and the problem.

mod cache;
mod mp4;

use std::cell::RefCell;
use std::collections::HashMap;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use parquet::file::reader::{ChunkReader, Length};

use crate::decode::{resize, to_chw};
use crate::episodes::Segments;
use crate::error::{Error, Result};
use crate::frames::{Fetched, FrameSource};
use crate::reader::{Data, EpisodeRows};
use crate::store::{DataFile, SeekRead, Store};
use cache::{DecoderCache, Span};
use mp4::Track;

/// An opened video file: its index and how to read it.
struct VideoFile {
    id: usize,
    file: DataFile,
    track: Track,
}

type Opened = Arc<OnceLock<std::result::Result<Arc<VideoFile>, String>>>;

/// The video features a loader reads.
pub(crate) struct VideoSource {
    store: Store,
    counter: Arc<AtomicU64>,
    data: Arc<Data>,
    /// Camera keys, in the source's order.
    cameras: Vec<String>,
    /// Per `episode_index`, one segment per camera.
    segments: Segments,
    tolerance_s: f64,
    files: Mutex<HashMap<String, Opened>>,
    next_id: AtomicUsize,
    decoders: Arc<DecoderCache>,
}

impl VideoSource {
    pub fn new(
        store: Store,
        counter: Arc<AtomicU64>,
        data: Arc<Data>,
        cameras: Vec<String>,
        segments: Segments,
        tolerance_s: f64,
        decoders: usize,
    ) -> Self {
        VideoSource {
            store,
            counter,
            data,
            cameras,
            segments,
            tolerance_s,
            files: Mutex::new(HashMap::new()),
            next_id: AtomicUsize::new(0),
            decoders: Arc::new(DecoderCache::new(decoders)),
        }
    }

    /// The file at `rel`, opened and indexed once.
    fn open(&self, rel: &str) -> Result<Arc<VideoFile>> {
        let cell = {
            let mut files = self
                .files
                .lock()
                .map_err(|_| Error::Stopped("video file table poisoned".into()))?;
            files.entry(rel.to_string()).or_default().clone()
        };
        let opened = cell.get_or_init(|| {
            let file = match self.store.file(rel, self.counter.clone()) {
                Ok(f) => f,
                Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                    return Err("video file missing".into())
                }
                Err(e) => return Err(e.to_string()),
            };
            let size = file.len();
            let track = Track::read(SeekRead::new(file.clone()), size)?;
            Ok(Arc::new(VideoFile {
                id: self.next_id.fetch_add(1, Ordering::Relaxed),
                file,
                track,
            }))
        });
        opened.clone().map_err(|reason| Error::Format {
            path: self.store.describe(rel),
            reason,
        })
    }

    /// One camera's span for `frames` of `ep`.
    fn span(&self, ep: &EpisodeRows, cam: usize, frames: Range<usize>) -> Result<CamSpan> {
        let key = &self.cameras[cam];
        let seg = self
            .segments
            .get(&ep.episode_index)
            .and_then(|s| s.get(cam))
            .ok_or_else(|| {
                Error::format(
                    self.store.describe("meta/episodes"),
                    format!("episode {} has no videos/{key} entry", ep.episode_index),
                )
            })?;
        crate::meta::check_template("video file", &seg.file)
            .map_err(|e| Error::format(self.store.describe("meta/episodes"), e))?;
        let video = self.open(&seg.file)?;
        let name = video.file.name.clone();
        let timestamps = self.data.timestamp.as_ref().ok_or_else(|| {
            Error::format(
                self.data.files[ep.file].file.name.clone(),
                "no timestamp column (video frames are found by it)",
            )
        })?;
        let track = &video.track;
        let mut targets = Vec::with_capacity(frames.len());
        for f in frames.clone() {
            let t_s = seg.from_s + f64::from(timestamps[ep.offset + f]);
            let (d, off) = track.nearest(t_s);
            if off >= self.tolerance_s {
                return Err(Error::Image {
                    path: name,
                    episode: ep.episode_index,
                    frame: f,
                    camera: key.clone(),
                    reason: format!(
                        "no frame at {t_s:.4} s (from_timestamp {:.4} + timestamp): the nearest is {:.4} s away, tolerance {} s",
                        seg.from_s, off, self.tolerance_s
                    ),
                });
            }
            targets.push(d as usize);
        }
        let first = targets
            .iter()
            .map(|&d| track.samples[d].keyframe as usize)
            .min()
            .unwrap_or(0);
        // With B-frames a picture can only come out once every picture shown before it in its
        // group was decoded, some of which come later in decode order.
        let last = targets
            .iter()
            .map(|&d| track.last_needed(d))
            .max()
            .unwrap_or(0);
        let samples = &track.samples[first..=last];
        let start = samples.iter().map(|s| s.offset).min().unwrap_or(0);
        let end = samples
            .iter()
            .map(|s| s.offset + u64::from(s.size))
            .max()
            .unwrap_or(0);
        if end > video.file.len() {
            return Err(Error::format(
                name,
                format!(
                    "cut short: {} bytes, but frames of episode {} reach byte {end}",
                    video.file.len(),
                    ep.episode_index
                ),
            ));
        }
        let bytes = video
            .file
            .get_bytes(start, (end - start) as usize)
            .map_err(|e| Error::format(name.clone(), e))?;
        let offsets = samples
            .iter()
            .map(|s| ((s.offset - start) as usize, s.size as usize))
            .collect();
        Ok(CamSpan {
            video,
            first,
            bytes,
            offsets,
            targets,
            base: frames.start,
        })
    }
}

impl FrameSource for VideoSource {
    fn fetch(&self, ep: &EpisodeRows, frames: Range<usize>) -> Result<Arc<dyn Fetched>> {
        let spans = (0..self.cameras.len())
            .map(|cam| self.span(ep, cam, frames.clone()))
            .collect::<Result<Vec<_>>>()?;
        Ok(Arc::new(FetchedVideo {
            spans,
            episode: ep.episode_index,
            cameras: self.cameras.clone(),
            decoders: self.decoders.clone(),
        }))
    }
}

/// One camera's compressed samples for some frames of an episode.
struct CamSpan {
    video: Arc<VideoFile>,
    /// Decode index of the first sample held.
    first: usize,
    bytes: bytes::Bytes,
    offsets: Vec<(usize, usize)>,
    /// Decode index of each fetched frame's sample.
    targets: Vec<usize>,
    /// Episode frame index of the first fetched frame.
    base: usize,
}

struct FetchedVideo {
    spans: Vec<CamSpan>,
    episode: i64,
    cameras: Vec<String>,
    decoders: Arc<DecoderCache>,
}

thread_local! {
    static SCRATCH: RefCell<(Vec<u8>, Vec<u8>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

impl Fetched for FetchedVideo {
    fn decode(
        &self,
        cam: usize,
        frame: usize,
        width: u32,
        height: u32,
        dst: &mut [u8],
    ) -> Result<()> {
        let span = &self.spans[cam];
        let err = |reason: String| Error::Image {
            path: span.video.file.name.clone(),
            episode: self.episode,
            frame,
            camera: self.cameras[cam].clone(),
            reason,
        };
        let target = frame
            .checked_sub(span.base)
            .and_then(|i| span.targets.get(i).copied())
            .ok_or_else(|| err("frame was not fetched (internal error)".into()))?;
        let held = Span {
            track_id: span.video.id,
            track: &span.video.track,
            first: span.first,
            bytes: &span.bytes,
            offsets: &span.offsets,
        };
        SCRATCH.with(|s| {
            let (rgb, resized) = &mut *s.borrow_mut();
            let mut size = (0, 0);
            // At the feature's size (the usual case) the picture goes straight to the
            // channel-first output; a picture of another size is resized through RGB first.
            self.decoders
                .picture(&held, target, &mut |p| {
                    size = (p.width as u32, p.height as u32);
                    if size == (width, height) {
                        p.write_chw(dst);
                    } else {
                        p.write_rgb(rgb);
                    }
                })
                .map_err(err)?;
            if size != (width, height) {
                resize(rgb, size.0, size.1, width, height, resized).map_err(err)?;
                to_chw(resized, width as usize, height as usize, dst);
            }
            Ok(())
        })
    }
}
