//! Camera video codecs without ffmpeg. Decoding: AV1 with `re_rav1d` (rerun's pure-Rust build
//! of rav1d) and H.264 with `openh264` (Cisco's decoder, compiled from its bundled C++ source),
//! to 8-bit 4:2:0 planes, and those planes to RGB bit-exact with what LeRobot sees through
//! PyAV. The loader decodes video features of LeRobot datasets with it (one MP4 sample at a
//! time); the converter decodes `foxglove_msgs/CompressedVideo` camera topics of recordings
//! (one Annex B access unit at a time).
//!
//! Encoding, for the converter's LeRobot v3 video features: RGB24 frames → 4:2:0 (BT.601
//! limited range) → H.264 (`openh264`) or AV1 (`rav1e`, pure Rust) with a keyframe every `gop`
//! frames and no reordering ([`VideoEncoder`]), and the encoded pieces (episodes) of one camera
//! → one MP4 file with one video track at a constant frame rate ([`mp4_file`]).

mod decode;
mod encode;
mod encode_av1;
mod encode_h264;
mod encoding;
mod mp4;
mod yuv;

#[cfg(test)]
mod roundtrip_tests;

pub use decode::{new_decoder, parse_avcc, Codec, Decode};
pub use encode::VideoEncoder;
pub use encoding::{EncodeError, EncodedVideo, VideoSettings, DEFAULT_AV1_SPEED};
pub use mp4::{mp4_file, Mp4Error};
pub use yuv::Yuv420;
