//! A rig's cameras in an episode: their frame streams (colour, then with depth kept each
//! camera's registered depth, aligned by the same frame rule), the frames chosen at each tick —
//! colour resized and JPEG- or video-encoded, depth kept as its values resized by nearest
//! neighbour — and each camera's intrinsics from its `camera_info`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rayon::prelude::*;
use scaledp_codec::{EncodedVideo, VideoEncoder, VideoSettings};
use scaledp_schema::rig::{Camera, DepthEncoding, Rig};

use crate::camera_info::{intrinsics_of, Intrinsics};
use crate::depth::DepthStats;
use crate::error::{Error, Result};
use crate::frames::FrameStore;
use crate::images::{ChannelHistogram, EncodeSpec, EncodedFrame};
use crate::options::ConvertOptions;
use crate::series::{messages_of, ordered, stamp_of};
use crate::source::Recording;
use crate::stats::Stats;
use scaledp_align::{Alignment, Stream};

/// One camera's frames of an episode.
#[derive(Debug, Clone)]
pub struct CameraFrames {
    /// Camera name (feature `observation.images.<name>`).
    pub name: String,
    /// JPEG bytes per frame (empty when the camera is stored as video).
    pub jpeg: Vec<Vec<u8>>,
    /// The frames encoded as one video stream, for a dataset of video features.
    pub video: Option<EncodedVideo>,
    /// Pixel statistics over the resized frames.
    pub histogram: ChannelHistogram,
    /// Intrinsics for the stored images, from the camera's `camera_info` (None without one, or
    /// when it does not describe the recorded images).
    pub intrinsics: Option<Intrinsics>,
    /// The camera's registered depth, when the rig records it and the conversion keeps it.
    pub depth: Option<DepthFrames>,
}

/// One camera's depth frames of an episode (feature `observation.depth.<name>`).
#[derive(Debug, Clone)]
pub struct DepthFrames {
    /// `16UC1` (millimetres) or `32FC1` (metres), as the camera published it.
    pub encoding: DepthEncoding,
    /// Per frame, the values at the stored image size, row-major, little-endian.
    pub frames: Vec<Vec<u8>>,
    /// Statistics over the measured pixels, in the source's unit.
    pub stats: Stats,
    /// The depth image's own `camera_info`, when the rig names one.
    pub intrinsics: Option<Intrinsics>,
}

/// A camera topic's frames in stamp order: the stream aligned on, and each frame's stored
/// ordinal.
pub(crate) struct CameraStream {
    pub stream: Stream,
    pub ordinals: Vec<usize>,
    pub reordered: usize,
}

/// The camera streams of an episode, in the order they are aligned: every camera's colour
/// stream (rig order), then the depth stream of each camera that has one (rig order).
pub(crate) struct CameraStreams {
    pub colour: Vec<CameraStream>,
    /// (camera index, its depth stream).
    pub depth: Vec<(usize, CameraStream)>,
}

impl CameraStreams {
    /// Every stream, colour then depth, as `align` takes them.
    pub fn all(&self) -> impl Iterator<Item = &CameraStream> {
        self.colour.iter().chain(self.depth.iter().map(|(_, s)| s))
    }
}

/// The cameras whose depth an episode keeps: with `opts.depth`, those the rig gives a depth
/// topic.
pub(crate) fn depth_cameras<'r>(
    rig: &'r Rig,
    opts: &ConvertOptions,
) -> impl Iterator<Item = (usize, &'r Camera)> {
    let keep = opts.depth;
    rig.cameras
        .iter()
        .enumerate()
        .filter(move |(_, c)| keep && c.depth.is_some())
}

/// A topic's frame stamps (only those logged inside the window), put in stamp order.
fn stream_of(
    path: &Path,
    topic: &str,
    fps: f64,
    what: &str,
    frames: &dyn FrameStore,
    opts: &ConvertOptions,
    silent: impl Fn() -> String,
) -> Result<CameraStream> {
    let (ordinals, stamps): (Vec<usize>, Vec<u64>) = frames
        .stamps(topic)
        .into_iter()
        .enumerate()
        .filter(|(_, (_, log))| opts.in_window(*log))
        .map(|(i, (header, log))| (i, stamp_of(header, log, opts)))
        .unzip();
    if stamps.is_empty() {
        return Err(Error::Rejected {
            path: path.into(),
            reason: format!("{what} ({topic}) {}", silent()),
        });
    }
    let ordered = ordered(path, topic, &stamps, opts.reorder_window_ns())?;
    Ok(CameraStream {
        stream: Stream::new(
            topic,
            ordered.order.iter().map(|&k| stamps[k]).collect(),
            Some(fps),
        ),
        ordinals: ordered.order.iter().map(|&k| ordinals[k]).collect(),
        reordered: ordered.reordered,
    })
}

/// Every camera's colour stream, then the depth streams kept.
pub(crate) fn camera_streams(
    path: &Path,
    rig: &Rig,
    frames: &dyn FrameStore,
    opts: &ConvertOptions,
) -> Result<CameraStreams> {
    let mut colour = Vec::with_capacity(rig.cameras.len());
    for c in &rig.cameras {
        let silent = || match c.video_codec() {
            Some(codec) => format!("has no {codec} frame that decodes"),
            None => "has no messages".into(),
        };
        let what = format!("camera '{}'", c.name);
        colour.push(stream_of(
            path, &c.topic, c.fps, &what, frames, opts, silent,
        )?);
    }
    let mut depth = Vec::new();
    for (ci, c) in depth_cameras(rig, opts) {
        let Some(d) = &c.depth else { continue };
        let silent = || "has no messages (convert with --no-depth to leave depth out)".to_string();
        let what = format!("depth of camera '{}'", c.name);
        depth.push((
            ci,
            stream_of(path, &d.topic, c.fps, &what, frames, opts, silent)?,
        ));
    }
    Ok(CameraStreams { colour, depth })
}

/// The frame a tick picked, from what the store encoded.
fn picked<'a>(
    path: &Path,
    done: &'a std::collections::HashMap<crate::FrameKey, EncodedFrame>,
    topic: &str,
    ordinal: usize,
) -> Result<&'a EncodedFrame> {
    done.get(&(topic.to_string(), ordinal))
        .ok_or_else(|| Error::Rejected {
            path: path.into(),
            reason: format!("frame {ordinal} of {topic} was not found on the second read"),
        })
}

/// What [`camera_frames`] works from.
pub(crate) struct Chosen<'a> {
    pub streams: &'a CameraStreams,
    pub aligned: &'a Alignment,
    /// Ticks kept (the last tick has no action and is dropped).
    pub frames: usize,
    pub spec: &'a EncodeSpec,
    pub video: Option<VideoSettings>,
}

/// Each camera's chosen frame at each of the first `frames` ticks — decoded, resized and
/// JPEG-encoded once (in parallel), or with `video` encoded as one stream per camera — with the
/// episode's pixel statistics; its depth frames when kept; its intrinsics.
pub(crate) fn camera_frames(
    path: &Path,
    rig: &Rig,
    rec: &Recording,
    store: &dyn FrameStore,
    at: &Chosen<'_>,
    opts: &ConvertOptions,
) -> Result<Vec<CameraFrames>> {
    let ticks = &at.aligned.frames[..at.frames];
    let n_colour = at.streams.colour.len();
    let mut wanted: BTreeMap<String, BTreeSet<usize>> = BTreeMap::new();
    for (ci, cam) in rig.cameras.iter().enumerate() {
        let s = &at.streams.colour[ci];
        let set = wanted.entry(cam.topic.clone()).or_default();
        set.extend(ticks.iter().map(|f| s.ordinals[f[ci]]));
    }
    for (di, (ci, s)) in at.streams.depth.iter().enumerate() {
        let topic = &rig.cameras[*ci].depth.as_ref().map(|d| d.topic.clone());
        let Some(topic) = topic else { continue };
        let set = wanted.entry(topic.clone()).or_default();
        set.extend(ticks.iter().map(|f| s.ordinals[f[n_colour + di]]));
    }
    let done = store.encode(path, &wanted, at.spec)?;
    let stored = (at.spec.width, at.spec.height);
    let one = |ci: usize| -> Result<CameraFrames> {
        let cam = &rig.cameras[ci];
        let s = &at.streams.colour[ci];
        let mut histogram = ChannelHistogram::default();
        let mut chosen = Vec::with_capacity(at.frames);
        for f in ticks {
            let e = picked(path, &done, &cam.topic, s.ordinals[f[ci]])?;
            if let Some(d) = e.depth {
                return Err(Error::Rejected {
                    path: path.into(),
                    reason: format!(
                        "camera '{}' ({}): a {} depth image where colour frames are expected",
                        cam.name,
                        cam.topic,
                        d.as_str()
                    ),
                });
            }
            histogram.absorb(&e.histogram);
            chosen.push(e);
        }
        let source = chosen
            .first()
            .map_or((0, 0), |e| (e.source.width, e.source.height));
        let (jpeg, video) = encode_colour(path, cam, &chosen, at)?;
        let intrinsics = cam.camera_info_topic.as_ref().and_then(|topic| {
            let msgs = messages_of(rec, topic, opts);
            intrinsics_of(path, &cam.name, topic, &msgs, source, stored)
        });
        let depth = match at.streams.depth.iter().position(|(c, _)| *c == ci) {
            Some(di) => Some(depth_frames(
                path,
                rec,
                cam,
                &done,
                at,
                n_colour + di,
                opts,
            )?),
            None => None,
        };
        Ok(CameraFrames {
            name: cam.name.clone(),
            jpeg,
            video,
            histogram,
            intrinsics,
            depth,
        })
    };
    // Encoded in parallel, but the error reported is the first camera's in rig order, so the
    // same bad input always reads the same way.
    let each: Vec<Result<CameraFrames>> = (0..rig.cameras.len()).into_par_iter().map(one).collect();
    each.into_iter().collect()
}

/// A camera's chosen frames as JPEG bytes, or as one video stream.
fn encode_colour(
    path: &Path,
    cam: &Camera,
    chosen: &[&EncodedFrame],
    at: &Chosen<'_>,
) -> Result<(Vec<Vec<u8>>, Option<EncodedVideo>)> {
    let Some(settings) = at.video else {
        return Ok((chosen.iter().map(|e| e.bytes.clone()).collect(), None));
    };
    let failed = |e: scaledp_codec::EncodeError| Error::Rejected {
        path: path.into(),
        reason: format!("camera '{}': {e}", cam.name),
    };
    let mut enc = VideoEncoder::new(settings, at.spec.width, at.spec.height).map_err(failed)?;
    for e in chosen {
        enc.push_rgb(&e.bytes).map_err(failed)?;
    }
    Ok((Vec::new(), Some(enc.finish().map_err(failed)?)))
}

/// The depth frames of `cam` chosen at each tick (stream `slot` of the alignment), each in
/// the encoding the rig declares, with their statistics and the depth's own intrinsics.
fn depth_frames(
    path: &Path,
    rec: &Recording,
    cam: &Camera,
    done: &std::collections::HashMap<crate::FrameKey, EncodedFrame>,
    at: &Chosen<'_>,
    slot: usize,
    opts: &ConvertOptions,
) -> Result<DepthFrames> {
    let Some(d) = &cam.depth else {
        return Err(Error::Rejected {
            path: path.into(),
            reason: format!("camera '{}' has no depth", cam.name),
        });
    };
    let di = slot - at.streams.colour.len();
    let s = &at.streams.depth[di].1;
    let mut stats = DepthStats::new(d.encoding);
    let mut frames = Vec::with_capacity(at.frames);
    let mut source = (0, 0);
    for f in &at.aligned.frames[..at.frames] {
        let e = picked(path, done, &d.topic, s.ordinals[f[slot]])?;
        if e.depth != Some(d.encoding) {
            return Err(Error::Rejected {
                path: path.into(),
                reason: format!(
                    "depth of camera '{}' ({}): {} images, the rig declares {}",
                    cam.name,
                    d.topic,
                    e.source.encoding,
                    d.encoding.as_str()
                ),
            });
        }
        source = (e.source.width, e.source.height);
        match d.encoding {
            DepthEncoding::U16Millimetres => stats.add(
                e.bytes
                    .chunks_exact(2)
                    .map(|b| f64::from(u16::from_le_bytes([b[0], b[1]]))),
            ),
            DepthEncoding::F32Metres => stats.add(
                e.bytes
                    .chunks_exact(4)
                    .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))),
            ),
        }
        frames.push(e.bytes.clone());
    }
    let intrinsics = d.camera_info_topic.as_ref().and_then(|topic| {
        let msgs = messages_of(rec, topic, opts);
        let stored = (at.spec.width, at.spec.height);
        intrinsics_of(path, &cam.name, topic, &msgs, source, stored)
    });
    Ok(DepthFrames {
        encoding: d.encoding,
        frames,
        stats: stats.finish(),
        intrinsics,
    })
}
