//! Camera topics recorded as video (`foxglove_msgs/msg/CompressedVideo`: H.264 Annex B or AV1,
//! no B-frames, keyframes carrying their parameter sets). A frame of a video cannot be decoded
//! on its own, so every frame of such a topic is decoded in stream order as the recording is
//! read ([`scaledp_codec`]) and handed on as the raw `sensor_msgs/Image` (rgb8, same stamp and
//! frame id) that the rest of the converter reads: frame stamps, alignment, the choice of
//! frames and their encoding are those of any raw camera.
//!
//! A frame that gives no picture (before the topic's first keyframe, an undecodable frame and
//! what follows it up to the next keyframe) is not one of the topic's frames; alignment picks
//! among the others and one warning per topic says how many were dropped and why. Decoding is
//! deterministic, so every read of a file drops the same frames and agrees on frame ordinals.
//! A topic whose format is not decoded (H.265, VP9) fails the input with one line.

use std::collections::BTreeMap;
use std::path::Path;

use scaledp_codec::{new_decoder, Codec, Decode};
use scaledp_schema::msg::{is_keyframe, CompressedVideo, Header, Image};
use scaledp_schema::RosMessage;

use crate::error::{Error, Result};

/// The message type of video camera topics.
pub(crate) const COMPRESSED_VIDEO: &str = "foxglove_msgs/msg/CompressedVideo";
/// What their frames become.
pub(crate) const IMAGE: &str = "sensor_msgs/msg/Image";

/// Whether a message type is a video camera topic's.
pub(crate) fn is_video(message_type: &str) -> bool {
    message_type == COMPRESSED_VIDEO
}

/// One topic's decoder and what it dropped.
#[derive(Default)]
struct Topic {
    /// None until the first keyframe, and again after a frame failed to decode.
    decoder: Option<(String, Box<dyn Decode>)>,
    frames: usize,
    dropped: usize,
    /// The first frame that failed to decode: (log time, why).
    first_error: Option<(u64, String)>,
}

/// The video topics of one read of one file, each decoded in stream order.
#[derive(Default)]
pub(crate) struct Transcoder {
    topics: BTreeMap<String, Topic>,
    rgb: Vec<u8>,
}

fn codec(format: &str) -> Option<Codec> {
    match format {
        "h264" => Some(Codec::H264),
        "av1" => Some(Codec::Av1),
        _ => None,
    }
}

impl Transcoder {
    /// Decodes the next `foxglove_msgs/CompressedVideo` message (CDR) of `topic`: the picture
    /// as a CDR `sensor_msgs/Image` in rgb8, or None when the frame gives none (see the module
    /// docs). Errs on a format that is not decoded.
    pub fn frame(
        &mut self,
        path: &Path,
        topic: &str,
        log_time_ns: u64,
        data: &[u8],
    ) -> Result<Option<Vec<u8>>> {
        let state = self.topics.entry(topic.to_string()).or_default();
        state.frames += 1;
        let msg = match CompressedVideo::from_cdr(data) {
            Ok(m) => m,
            Err(e) => {
                drop_frame(
                    state,
                    log_time_ns,
                    format!("not a CompressedVideo message: {e}"),
                );
                return Ok(None);
            }
        };
        let Some(codec) = codec(&msg.format) else {
            return Err(Error::Message {
                path: path.into(),
                topic: topic.into(),
                log_time_ns,
                reason: format!(
                    "video in format {:?}: only h264 and av1 CompressedVideo topics are decoded",
                    msg.format
                ),
            });
        };
        if state
            .decoder
            .as_ref()
            .is_some_and(|(format, _)| *format != msg.format)
        {
            state.decoder = None;
        }
        if state.decoder.is_none() {
            if !is_keyframe(&msg.format, &msg.data) {
                state.dropped += 1;
                return Ok(None);
            }
            match new_decoder(codec, &[]) {
                Ok(d) => state.decoder = Some((msg.format.clone(), d)),
                Err(e) => {
                    drop_frame(state, log_time_ns, e);
                    return Ok(None);
                }
            }
        }
        let Some((_, dec)) = state.decoder.as_mut() else {
            return Ok(None);
        };
        let rgb = &mut self.rgb;
        let mut size = None;
        let pushed = dec.push(&msg.data, &mut |p| {
            p.write_rgb(rgb);
            size = Some((p.width, p.height));
        });
        let (width, height) = match (pushed, size) {
            (Ok(()), Some(s)) => s,
            (Ok(()), None) => {
                drop_frame(state, log_time_ns, "the decoder gave no picture".into());
                return Ok(None);
            }
            (Err(e), _) => {
                drop_frame(state, log_time_ns, e);
                return Ok(None);
            }
        };
        let image = Image {
            header: Header {
                stamp: msg.timestamp,
                frame_id: msg.frame_id,
            },
            height: height as u32,
            width: width as u32,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: (width * 3) as u32,
            data: std::mem::take(&mut self.rgb),
        };
        let cdr = image.to_cdr();
        self.rgb = image.data;
        Ok(Some(cdr))
    }

    /// One warning per topic that dropped frames, naming the file, the count and the first
    /// failure.
    pub fn warn_dropped(&self, path: &Path) {
        for (topic, t) in &self.topics {
            if t.dropped == 0 {
                continue;
            }
            let why = match &t.first_error {
                Some((at, e)) => format!("the first undecodable at {at} ns: {e}"),
                None => "before its first keyframe".into(),
            };
            tracing::warn!(
                "{}: {topic}: {} of {} video frames gave no picture ({why}); aligned with the others",
                path.display(),
                t.dropped,
                t.frames
            );
        }
    }
}

/// Counts a frame that failed: the decoder is dropped, the next keyframe starts a new one.
fn drop_frame(state: &mut Topic, log_time_ns: u64, reason: String) {
    state.dropped += 1;
    state.decoder = None;
    state.first_error.get_or_insert((log_time_ns, reason));
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use openh264::encoder::{Encoder, EncoderConfig, IntraFramePeriod};
    use openh264::formats::{RgbSliceU8, YUVBuffer};
    use openh264::OpenH264API;
    use scaledp_schema::msg::Time;

    const W: usize = 64;
    const H: usize = 48;

    /// A picture that moves with `i`: smooth gradients, what H.264 keeps well.
    fn picture(i: usize) -> Vec<u8> {
        let mut p = Vec::with_capacity(W * H * 3);
        for y in 0..H {
            for x in 0..W {
                p.extend_from_slice(&[(x * 3 + i * 4) as u8, (y * 4) as u8, 128]);
            }
        }
        p
    }

    /// `n` frames as CompressedVideo CDR messages; an IDR at frame 0 and at each of `idr`.
    fn stream(n: usize, idr: &[usize]) -> Vec<Vec<u8>> {
        let config = EncoderConfig::new()
            .intra_frame_period(IntraFramePeriod::from_num_frames(1000))
            .num_threads(1);
        let mut enc = Encoder::with_api_config(OpenH264API::from_source(), config).unwrap();
        (0..n)
            .map(|i| {
                if idr.contains(&i) {
                    enc.force_intra_frame();
                }
                let yuv = YUVBuffer::from_rgb_source(RgbSliceU8::new(&picture(i), (W, H)));
                let data = enc.encode(&yuv).unwrap().to_vec();
                CompressedVideo {
                    timestamp: Time::from_ns(1_000 + i as u64),
                    frame_id: "cam".into(),
                    data,
                    format: "h264".into(),
                }
                .to_cdr()
            })
            .collect()
    }

    fn run(t: &mut Transcoder, msgs: &[Vec<u8>]) -> Vec<Option<Image>> {
        let path = Path::new("rec.mcap");
        msgs.iter()
            .enumerate()
            .map(|(i, m)| {
                t.frame(path, "/cam", i as u64, m)
                    .unwrap()
                    .map(|cdr| Image::from_cdr(&cdr).unwrap())
            })
            .collect()
    }

    #[test]
    fn every_frame_of_an_h264_stream_becomes_its_rgb8_picture_with_its_stamp() {
        let out = run(&mut Transcoder::default(), &stream(8, &[]));
        for (i, img) in out.iter().enumerate() {
            let img = img.as_ref().unwrap();
            assert_eq!(
                (img.width, img.height, img.step),
                (W as u32, H as u32, W as u32 * 3)
            );
            assert_eq!(img.encoding, "rgb8");
            assert_eq!(img.header.stamp.as_ns(), 1_000 + i as u64);
            assert_eq!(img.header.frame_id, "cam");
            let want = picture(i);
            let diff: u64 = img
                .data
                .iter()
                .zip(&want)
                .map(|(a, b)| u64::from(a.abs_diff(*b)))
                .sum();
            let mean = diff as f64 / want.len() as f64;
            assert!(mean < 6.0, "frame {i}: mean difference {mean:.2} levels");
        }
    }

    /// Cuts a frame to its first bytes (its start code): undecodable.
    fn cut(msg: &mut Vec<u8>) {
        let mut f = CompressedVideo::from_cdr(msg).unwrap();
        f.data.truncate(6);
        *msg = f.to_cdr();
    }

    /// Which frames gave a picture.
    fn decoded(t: &mut Transcoder, msgs: &[Vec<u8>]) -> Vec<bool> {
        run(t, msgs).iter().map(Option::is_some).collect()
    }

    #[test]
    fn frames_before_the_first_keyframe_and_after_a_corrupt_one_are_dropped_until_the_next() {
        let mut msgs = stream(10, &[6]);
        // The stream joined late: frames 0 (the IDR) is missing.
        msgs.remove(0);
        // Frame 3 (index 2 now) cut to its start code: undecodable.
        cut(&mut msgs[2]);
        let mut t = Transcoder::default();
        let got = decoded(&mut t, &msgs);
        // P-frames 1-5 have no keyframe before them; the IDR at 6 starts the decoder.
        assert_eq!(
            got,
            [false, false, false, false, false, true, true, true, true]
        );
        let state = &t.topics["/cam"];
        assert_eq!((state.frames, state.dropped), (9, 5));

        let mut msgs = stream(10, &[6]);
        cut(&mut msgs[3]);
        let mut t = Transcoder::default();
        let got = decoded(&mut t, &msgs);
        assert_eq!(
            got,
            [true, true, true, false, false, false, true, true, true, true]
        );
        let (at, why) = t.topics["/cam"].first_error.clone().unwrap();
        assert_eq!(at, 3, "{why}");
    }

    #[test]
    fn a_format_that_is_not_decoded_is_one_error_naming_file_topic_and_format() {
        let msg = CompressedVideo {
            format: "h265".into(),
            data: vec![0, 0, 0, 1, 0x40, 1],
            ..Default::default()
        }
        .to_cdr();
        let e = Transcoder::default()
            .frame(Path::new("rec.mcap"), "/cam", 5, &msg)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("rec.mcap") && e.contains("/cam") && e.contains("h265"),
            "{e}"
        );
        let garbage = Transcoder::default()
            .frame(Path::new("rec.mcap"), "/cam", 5, &[1, 2, 3])
            .unwrap();
        assert!(garbage.is_none());
    }
}
