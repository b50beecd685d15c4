//! Camera streams: raw and compressed images, compressed video, and a cheap look at an image's
//! size and encoding.

use super::base::{Header, RosMessage, Time};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::Result;

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Image {
    /// Capture stamp and camera frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding, e.g. `bgra8`, `rgb8`, `16UC1`, `32FC1`.
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row (may exceed width × bytes per pixel).
    pub step: u32,
    /// `step × height` bytes.
    pub data: Vec<u8>,
}

impl RosMessage for Image {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Image";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.encoding);
        w.u8(self.is_bigendian);
        w.u32(self.step);
        w.bytes(&self.data);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?,
            is_bigendian: r.u8()?,
            step: r.u32()?,
            data: r.bytes()?.to_vec(),
        })
    }
}

/// An image's size and encoding, without its pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageLayout {
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding.
    pub encoding: String,
}

/// Reads the size and encoding of a `sensor_msgs/Image` payload without touching its pixels:
/// cheap enough for every received frame.
pub fn image_layout(payload: &[u8]) -> Result<ImageLayout> {
    let mut r = CdrReader::new(payload)?;
    Header::read(&mut r)?;
    Ok(ImageLayout {
        height: r.u32()?,
        width: r.u32()?,
        encoding: r.string()?,
    })
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CompressedImage {
    /// Capture stamp and camera frame.
    pub header: Header,
    /// `jpeg` or `png` (image_transport may add details, e.g. `rgb8; jpeg compressed bgr8`).
    pub format: String,
    /// The encoded image.
    pub data: Vec<u8>,
}

impl RosMessage for CompressedImage {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/CompressedImage";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.format);
        w.bytes(&self.data);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            format: r.string()?,
            data: r.bytes()?.to_vec(),
        })
    }
}

/// `foxglove_msgs/msg/CompressedVideo` (foxglove schemas; `foxglove.CompressedVideo` over
/// protobuf): one frame of a compressed video stream. For `h264` / `h265` the data is one
/// access unit in Annex B (start codes), keyframes carrying their parameter sets, no B-frames;
/// for `av1` one temporal unit of OBUs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CompressedVideo {
    /// Capture stamp (the first field, as `header.stamp` is elsewhere).
    pub timestamp: Time,
    /// Camera frame.
    pub frame_id: String,
    /// The compressed frame.
    pub data: Vec<u8>,
    /// `h264`, `h265`, `vp9` or `av1`.
    pub format: String,
}

impl RosMessage for CompressedVideo {
    const TYPE_NAME: &'static str = "foxglove_msgs/msg/CompressedVideo";
    fn write(&self, w: &mut CdrWriter) {
        self.timestamp.write(w);
        w.string(&self.frame_id);
        w.bytes(&self.data);
        w.string(&self.format);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            timestamp: Time::read(r)?,
            frame_id: r.string()?,
            data: r.bytes()?.to_vec(),
            format: r.string()?,
        })
    }
}

impl CompressedVideo {
    /// Whether the frame can be decoded on its own (a decoder may start here): for `h264` an
    /// IDR slice (NAL type 5), for `h265` an IRAP picture (NAL types 16-23), for `av1` a
    /// temporal unit carrying a sequence header (OBU type 1). Unknown formats: false.
    pub fn is_keyframe(&self) -> bool {
        is_keyframe(&self.format, &self.data)
    }
}

/// [`CompressedVideo::is_keyframe`] on a frame's `format` and `data`.
pub fn is_keyframe(format: &str, data: &[u8]) -> bool {
    match format {
        "h264" => annex_b_nal_types(data).any(|h| h & 0x1F == 5),
        "h265" => annex_b_nal_types(data).any(|h| (16..=23).contains(&((h >> 1) & 0x3F))),
        "av1" => av1_obu_types(data).any(|t| t == 1),
        _ => false,
    }
}

/// The first byte of every NAL unit of an Annex B stream (after 3- or 4-byte start codes).
fn annex_b_nal_types(data: &[u8]) -> impl Iterator<Item = u8> + '_ {
    data.windows(4)
        .filter(|w| w[..3] == [0, 0, 1])
        .map(|w| w[3])
}

/// OBU types of a low-overhead AV1 temporal unit (every OBU with its size field).
fn av1_obu_types(data: &[u8]) -> impl Iterator<Item = u8> + '_ {
    let mut at = 0usize;
    std::iter::from_fn(move || {
        let h = *data.get(at)?;
        let kind = (h >> 3) & 0x0F;
        let mut p = at + 1 + usize::from((h >> 2) & 1);
        if (h >> 1) & 1 == 0 {
            at = data.len();
            return Some(kind);
        }
        let mut size = 0usize;
        for i in 0..8 {
            let b = *data.get(p)?;
            p += 1;
            size |= usize::from(b & 0x7F) << (7 * i);
            if b & 0x80 == 0 {
                break;
            }
        }
        at = p.checked_add(size)?;
        Some(kind)
    })
}
