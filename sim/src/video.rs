//! Cameras published as compressed video (`foxglove_msgs/msg/CompressedVideo`, a rig camera with
//! `encoding = "h264"`, or `scaledp sim --camera-codec h264`), as a robot PC publishes them to
//! keep 2×720p off the disk: H.264 from OpenH264 (Constrained Baseline: no B-frames), each
//! message one access unit in Annex B, an IDR with SPS/PPS once a second.

use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, IntraFramePeriod, RateControlMode, UsageType,
};
use openh264::formats::{BgraSliceU8, RgbSliceU8, RgbaSliceU8, YUVBuffer};
use openh264::OpenH264API;
use scaledp_schema::msg::{CompressedVideo, Time};
use scaledp_schema::rig::Camera;
use scaledp_schema::RosMessage;

/// The raw encoding a camera is rendered in: its own, or for a video camera its model's.
pub(crate) fn raw_encoding(cam: &Camera) -> &str {
    match cam.video_codec() {
        Some(_) => cam.model.default_encoding(),
        None => cam.encoding(),
    }
}

/// One camera's encoder.
pub(crate) struct VideoEncoder {
    enc: Encoder,
    width: usize,
    height: usize,
    encoding: String,
}

impl VideoEncoder {
    /// An encoder for `cam` (which must have a video codec the simulator encodes: `h264`).
    pub fn new(cam: &Camera) -> Result<Self, String> {
        match cam.video_codec() {
            Some("h264") => {}
            other => {
                return Err(format!(
                    "camera '{}': the simulator encodes h264 video, not {other:?}",
                    cam.name
                ))
            }
        }
        // ~0.2 bit per pixel: sharp at the simulator's sizes; one IDR per second.
        let bps = (f64::from(cam.width) * f64::from(cam.height) * cam.fps * 0.2) as u32;
        let config = EncoderConfig::new()
            .usage_type(UsageType::CameraVideoRealTime)
            .rate_control_mode(RateControlMode::Bitrate)
            .bitrate(BitRate::from_bps(bps.max(100_000)))
            .max_frame_rate(FrameRate::from_hz(cam.fps as f32))
            .intra_frame_period(IntraFramePeriod::from_num_frames(
                cam.fps.round().max(1.0) as u32
            ))
            .skip_frames(false)
            .num_threads(1);
        let enc = Encoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| format!("camera '{}': H.264 encoder: {e}", cam.name))?;
        Ok(VideoEncoder {
            enc,
            width: cam.width as usize,
            height: cam.height as usize,
            encoding: raw_encoding(cam).to_string(),
        })
    }

    /// Encodes one rendered frame (tightly packed rows in the camera's raw encoding) into one
    /// Annex B access unit.
    pub fn encode(&mut self, raw: &[u8]) -> Result<Vec<u8>, String> {
        let dims = (self.width, self.height);
        let yuv = match self.encoding.as_str() {
            "rgb8" => YUVBuffer::from_rgb_source(RgbSliceU8::new(raw, dims)),
            "rgba8" => YUVBuffer::from_rgb_source(RgbaSliceU8::new(raw, dims)),
            "bgra8" => YUVBuffer::from_rgb_source(BgraSliceU8::new(raw, dims)),
            other => return Err(format!("cannot encode {other} frames as H.264")),
        };
        let au = self.enc.encode(&yuv).map_err(|e| format!("H.264: {e}"))?;
        Ok(au.to_vec())
    }
}

/// The encoders of a rig's cameras: one for each video camera.
pub(crate) fn encoders(cameras: &[Camera]) -> crate::Result<Vec<Option<VideoEncoder>>> {
    cameras
        .iter()
        .map(|c| match c.video_codec() {
            Some(_) => VideoEncoder::new(c).map(Some).map_err(crate::Error::Video),
            None => Ok(None),
        })
        .collect()
}

/// A rendered frame (in `raw_encoding(cam)`) of a video camera as a `CompressedVideo` payload;
/// a frame the encoder refuses is logged and sent empty, as a camera driver drops a frame.
pub(crate) fn video_message(
    cam: &Camera,
    enc: &mut VideoEncoder,
    raw: &[u8],
    stamp_ns: u64,
) -> Vec<u8> {
    let data = enc.encode(raw).unwrap_or_else(|e| {
        tracing::warn!("{}: {e}", cam.topic);
        Vec::new()
    });
    CompressedVideo {
        timestamp: Time::from_ns(stamp_ns),
        frame_id: format!("{}_camera_optical_frame", cam.name),
        data,
        format: "h264".into(),
    }
    .to_cdr()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_become_annex_b_access_units_with_an_idr_first() {
        let text = include_str!("../../rigs/franka_sim.toml").replacen(
            "fps = 30.0",
            "fps = 30.0\nencoding = \"h264\"",
            1,
        );
        let rig = scaledp_schema::Rig::parse(&text, std::path::Path::new("t.toml")).unwrap();
        let cam = &rig.cameras[0];
        assert_eq!(raw_encoding(cam), "bgra8");
        let mut enc = VideoEncoder::new(cam).unwrap();
        let frame = vec![90u8; cam.width as usize * cam.height as usize * 4];
        let first = enc.encode(&frame).unwrap();
        assert!(first.starts_with(&[0, 0, 0, 1]), "{:?}", &first[..8]);
        // NAL types present: SPS (7), PPS (8), IDR slice (5).
        let types: Vec<u8> = first
            .windows(5)
            .filter(|w| w[..4] == [0, 0, 0, 1])
            .map(|w| w[4] & 0x1F)
            .collect();
        assert!(
            types.contains(&7) && types.contains(&8) && types.contains(&5),
            "{types:?}"
        );
        let second = enc.encode(&frame).unwrap();
        assert!(!second.is_empty() && second.len() < first.len());
        let mut raw_cam = cam.clone();
        raw_cam.encoding = None;
        assert!(VideoEncoder::new(&raw_cam).is_err());
    }
}
