//! What an encoder takes and gives, shared by the front ([`crate::encode`]) and its backends
//! (H.264, AV1): the settings, the encoded video, the errors, and the planes and samples that
//! pass between them.

use crate::decode::Codec;

/// How a camera is encoded (LeRobot's defaults: AV1, yuv420p, g=2, crf 30).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoSettings {
    /// The codec.
    pub codec: Codec,
    /// Frames per second (rate control and stream timing only: [`crate::mp4_file`] stamps the
    /// samples).
    pub fps: f64,
    /// A keyframe every `gop` frames (1: all keyframes).
    pub gop: u32,
    /// Constant quality on AV1's 0–63 scale (lower is better). H.264 is encoded at QP
    /// `crf` clamped to 1–51; AV1 at rav1e quantizer `round(crf × 255 / 63)`.
    pub crf: u8,
    /// rav1e's speed preset (0 slowest … 10 fastest), AV1 only.
    pub av1_speed: u8,
}

/// rav1e's preset in [`VideoSettings::lerobot`], chosen for throughput. Measured with
/// `encode_speed` (an ignored test of this crate; one encoder, synthetic frames, 2 cores, rav1e
/// without assembly, which runs one tile on one core at these sizes): frames/s at 84×84 and
/// 320×240 were 30 and 3.5 at preset 6, 52 and 6.1 at 8, 106 and 10.1 at 10, for 26 % and 8 %
/// more bytes at 10 than at 6 (crf 30, gop 2).
pub const DEFAULT_AV1_SPEED: u8 = 10;

impl VideoSettings {
    /// LeRobot's defaults for `codec` at `fps`: a keyframe every 2 frames, crf 30, and
    /// [`DEFAULT_AV1_SPEED`].
    pub fn lerobot(codec: Codec, fps: f64) -> Self {
        VideoSettings {
            codec,
            fps,
            gop: 2,
            crf: 30,
            av1_speed: DEFAULT_AV1_SPEED,
        }
    }
}

/// One camera's encoded frames, ready to mux.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedVideo {
    /// The codec.
    pub codec: Codec,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// The sample entry's configuration record payload: `avcC` (AVCDecoderConfigurationRecord,
    /// 4-byte NAL lengths) for H.264, `av1C` (AV1CodecConfigurationRecord with the sequence
    /// header OBU as configOBUs) for AV1. Equal for equal settings and size, so that pieces
    /// encoded separately can share one MP4 track.
    pub config: Vec<u8>,
    /// MP4 samples in decode = presentation order: H.264 access units as 4-byte
    /// length-prefixed NAL units (the parameter sets of `config` removed), AV1 temporal units
    /// (OBUs with size fields, no temporal delimiter; keyframes repeat the sequence header).
    pub samples: Vec<Vec<u8>>,
    /// Sync samples (keyframes), one flag per sample.
    pub keyframes: Vec<bool>,
}

/// Why a video could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// H.264 in 4:2:0 needs even dimensions.
    #[error("H.264 in 4:2:0 needs an even width and height, not {width}×{height}")]
    OddSize {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
    },
    /// A dimension too small (rav1e's minimum) or too large.
    #[error("frame size {width}×{height}: width and height must be {MIN_SIDE} to {MAX_SIDE}")]
    BadSize {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
    },
    /// A frame's byte count is not `width × height × 3`.
    #[error("frame of {got} bytes: {width}×{height} RGB24 is {expected}")]
    FrameLength {
        /// Bytes given.
        got: usize,
        /// Bytes expected.
        expected: usize,
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
    },
    /// A setting out of range.
    #[error("video settings: {0}")]
    Settings(String),
    /// `finish` before any frame.
    #[error("no frame was pushed: there is no video to encode")]
    NoFrames,
    /// The encoder library failed.
    #[error("{codec} encoder: {message}")]
    Encoder {
        /// "H.264" or "AV1".
        codec: &'static str,
        /// What it said.
        message: String,
    },
}

/// Smallest width or height accepted (rav1e's minimum; openh264 encodes 16×16 too).
pub(crate) const MIN_SIDE: u32 = 16;
/// Largest width or height accepted.
pub(crate) const MAX_SIDE: u32 = 16384;

/// Encoded samples as they come out of a backend.
#[derive(Default)]
pub(crate) struct Samples {
    pub samples: Vec<Vec<u8>>,
    pub keyframes: Vec<bool>,
}

/// 4:2:0 planes of one frame, without padding.
pub(crate) struct Planes<'a> {
    pub width: usize,
    pub height: usize,
    pub y: &'a [u8],
    pub u: &'a [u8],
    pub v: &'a [u8],
}
