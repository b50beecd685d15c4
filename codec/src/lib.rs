//! Camera video codecs, decoded without ffmpeg: AV1 with `re_rav1d` (rerun's pure-Rust build
//! of rav1d) and H.264 with `openh264` (Cisco's decoder, compiled from its bundled C++ source),
//! to 8-bit 4:2:0 planes, and those planes to RGB bit-exact with what LeRobot sees through
//! PyAV. The loader decodes video features of LeRobot datasets with it (one MP4 sample at a
//! time); the converter decodes `foxglove_msgs/CompressedVideo` camera topics of recordings
//! (one Annex B access unit at a time).

mod decode;
mod yuv;

pub use decode::{new_decoder, parse_avcc, Codec, Decode};
pub use yuv::Yuv420;
