//! Video encoding from packed RGB24 frames, without ffmpeg: H.264 with `openh264` (Cisco's
//! encoder, from its bundled C++ source) and AV1 with `rav1e` (pure Rust, no nasm). Frames are
//! converted to 8-bit 4:2:0 (BT.601 limited range, as libswscale does for LeRobot) and encoded
//! with a keyframe every `gop` frames and no reordering, so each frame gives exactly one MP4
//! sample, in presentation order, ready for [`crate::mp4_file`].

use crate::decode::Codec;
use crate::encode_av1::Av1Encoder;
use crate::encode_h264::H264Encoder;
use crate::encoding::{EncodeError, EncodedVideo, VideoSettings};
use crate::encoding::{Planes, Samples, MAX_SIDE, MIN_SIDE};
use crate::yuv::rgb_to_yuv420;

enum Backend {
    H264(Box<H264Encoder>),
    Av1(Box<Av1Encoder>),
}

/// Encodes one camera's frames (RGB24) to [`EncodedVideo`].
pub struct VideoEncoder {
    settings: VideoSettings,
    width: u32,
    height: u32,
    backend: Backend,
    /// Y, U and V planes of the frame being pushed.
    yuv: Vec<u8>,
    out: Samples,
    frames: usize,
}

impl VideoEncoder {
    /// A new encoder for frames of `width × height` (even for H.264).
    pub fn new(settings: VideoSettings, width: u32, height: u32) -> Result<Self, EncodeError> {
        if !(MIN_SIDE..=MAX_SIDE).contains(&width) || !(MIN_SIDE..=MAX_SIDE).contains(&height) {
            return Err(EncodeError::BadSize { width, height });
        }
        if settings.codec == Codec::H264 && (width % 2 == 1 || height % 2 == 1) {
            return Err(EncodeError::OddSize { width, height });
        }
        let bad = |m: String| Err(EncodeError::Settings(m));
        if !(settings.fps.is_finite() && settings.fps > 0.0) {
            return bad(format!("{} fps: must be finite and positive", settings.fps));
        }
        if settings.gop == 0 {
            return bad("a keyframe every 0 frames: gop must be at least 1".into());
        }
        if settings.crf > 63 {
            return bad(format!("crf {}: must be 0 to 63", settings.crf));
        }
        let backend = match settings.codec {
            Codec::H264 => Backend::H264(Box::new(H264Encoder::new(&settings)?)),
            Codec::Av1 => Backend::Av1(Box::new(Av1Encoder::new(&settings, width, height)?)),
        };
        let (w, h) = (width as usize, height as usize);
        let chroma = w.div_ceil(2) * h.div_ceil(2);
        Ok(VideoEncoder {
            settings,
            width,
            height,
            backend,
            yuv: vec![0; w * h + 2 * chroma],
            out: Samples::default(),
            frames: 0,
        })
    }

    /// The settings this encoder was made with.
    pub fn settings(&self) -> &VideoSettings {
        &self.settings
    }

    /// Encodes one frame: packed RGB24 rows, `width × height × 3` bytes.
    pub fn push_rgb(&mut self, rgb: &[u8]) -> Result<(), EncodeError> {
        let (w, h) = (self.width as usize, self.height as usize);
        if rgb.len() != w * h * 3 {
            return Err(EncodeError::FrameLength {
                got: rgb.len(),
                expected: w * h * 3,
                width: self.width,
                height: self.height,
            });
        }
        let chroma = w.div_ceil(2) * h.div_ceil(2);
        let (y, uv) = self.yuv.split_at_mut(w * h);
        let (u, v) = uv.split_at_mut(chroma);
        rgb_to_yuv420(rgb, w, h, y, u, v);
        let planes = Planes {
            width: w,
            height: h,
            y,
            u,
            v,
        };
        match &mut self.backend {
            Backend::H264(e) => e.push(&planes, self.frames, &mut self.out)?,
            Backend::Av1(e) => e.push(&planes, &mut self.out)?,
        }
        self.frames += 1;
        Ok(())
    }

    /// Flushes the encoder: exactly one sample per pushed frame, in order.
    pub fn finish(mut self) -> Result<EncodedVideo, EncodeError> {
        if self.frames == 0 {
            return Err(EncodeError::NoFrames);
        }
        let (config, name) = match self.backend {
            Backend::H264(e) => (e.finish()?, "H.264"),
            Backend::Av1(e) => (e.finish(&mut self.out)?, "AV1"),
        };
        if self.out.keyframes.first() == Some(&false) {
            return Err(EncodeError::Encoder {
                codec: name,
                message: "the first frame is not a keyframe".into(),
            });
        }
        if self.out.samples.len() != self.frames || self.out.keyframes.len() != self.frames {
            return Err(EncodeError::Encoder {
                codec: name,
                message: format!(
                    "{} samples for {} frames",
                    self.out.samples.len(),
                    self.frames
                ),
            });
        }
        Ok(EncodedVideo {
            codec: self.settings.codec,
            width: self.width,
            height: self.height,
            config,
            samples: self.out.samples,
            keyframes: self.out.keyframes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_sizes_frames_and_settings_are_refused() {
        let h264 = VideoSettings::lerobot(Codec::H264, 30.0);
        let av1 = VideoSettings::lerobot(Codec::Av1, 30.0);
        let err = VideoEncoder::new(h264, 63, 48).err().unwrap();
        assert!(matches!(err, EncodeError::OddSize { .. }), "{err}");
        assert_eq!(
            err.to_string(),
            "H.264 in 4:2:0 needs an even width and height, not 63×48"
        );
        assert!(VideoEncoder::new(av1, 63, 47).is_ok());
        for (w, h) in [(0, 48), (15, 48), (64, 16385)] {
            let err = VideoEncoder::new(av1, w, h).err().unwrap();
            assert!(matches!(err, EncodeError::BadSize { .. }), "{err}");
        }
        assert_eq!(
            VideoEncoder::new(h264, 8, 8).err().unwrap().to_string(),
            "frame size 8×8: width and height must be 16 to 16384"
        );
        for s in [
            VideoSettings { gop: 0, ..h264 },
            VideoSettings { crf: 64, ..av1 },
            VideoSettings { fps: 0.0, ..av1 },
            VideoSettings {
                fps: f64::NAN,
                ..h264
            },
        ] {
            let err = VideoEncoder::new(s, 64, 48).err().unwrap();
            assert!(matches!(err, EncodeError::Settings(_)), "{err}");
        }
        for s in [h264, av1] {
            let mut enc = VideoEncoder::new(s, 64, 48).unwrap();
            let err = enc.push_rgb(&[0; 64 * 48 * 3 - 1]).unwrap_err();
            assert_eq!(err.to_string(), "frame of 9215 bytes: 64×48 RGB24 is 9216");
            assert!(matches!(enc.finish(), Err(EncodeError::NoFrames)));
        }
    }

    #[test]
    fn encoders_are_send() {
        fn send<T: Send>() {}
        send::<VideoEncoder>();
    }
}
