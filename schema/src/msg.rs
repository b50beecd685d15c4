//! The ROS 2 messages scaledp reads and writes, with CDR encoding and their `ros2msg` definitions.
//!
//! Definitions are composed the way rosbag2 (and Python `rosbags`) write them into MCAP schemas:
//! the root `.msg` text, then each dependency depth-first in declaration order, deduplicated, each
//! introduced by a line of 80 `=` and `MSG: pkg/Type`.

use crate::cdr::{CdrReader, CdrWriter};
use crate::error::Result;

/// A ROS 2 message type with a CDR encoding.
pub trait RosMessage: Sized {
    /// Full type name, e.g. `sensor_msgs/msg/Image`.
    const TYPE_NAME: &'static str;
    /// Writes the fields (no encapsulation header).
    fn write(&self, w: &mut CdrWriter);
    /// Reads the fields (after the encapsulation header).
    fn read(r: &mut CdrReader<'_>) -> Result<Self>;

    /// Serializes to a little-endian CDR payload, header included.
    fn to_cdr(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.write(&mut w);
        w.finish()
    }
    /// Parses a CDR payload (either byte order), header included.
    fn from_cdr(data: &[u8]) -> Result<Self> {
        Self::read(&mut CdrReader::new(data)?)
    }
    /// The `ros2msg` schema text rosbag2 stores for this type.
    fn definition() -> String {
        definition(Self::TYPE_NAME).unwrap_or_default()
    }
}

/// `.msg` text and direct dependencies of every type this crate knows, keyed by `pkg/Type`.
const DEFS: &[(&str, &str, &[&str])] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n", &[]),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
        &["builtin_interfaces/Time"],
    ),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        &["std_msgs/Header"],
    ),
    (
        "sensor_msgs/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
        &["std_msgs/Header"],
    ),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        &["std_msgs/Header"],
    ),
    (
        "foxglove_msgs/CompressedVideo",
        "builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\nstring format\n",
        &["builtin_interfaces/Time"],
    ),
    (
        "rosgraph_msgs/Clock",
        "builtin_interfaces/Time clock\n",
        &["builtin_interfaces/Time"],
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n", &[]),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n", &[]),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        &["geometry_msgs/Point", "geometry_msgs/Quaternion"],
    ),
    (
        "geometry_msgs/PoseStamped",
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        &["std_msgs/Header", "geometry_msgs/Pose"],
    ),
];

/// The `ros2msg` definition of a known type (`sensor_msgs/msg/Image` or `sensor_msgs/Image`).
pub fn definition(type_name: &str) -> Option<String> {
    let short = type_name.replacen("/msg/", "/", 1);
    let lookup = |name: &str| DEFS.iter().find(|(n, _, _)| *n == name);
    let (_, root, deps) = lookup(&short)?;
    let mut order: Vec<&str> = Vec::new();
    fn visit<'a>(deps: &[&'a str], order: &mut Vec<&'a str>) {
        for d in deps {
            if !order.contains(d) {
                order.push(d);
                if let Some((_, _, sub)) = DEFS.iter().find(|(n, _, _)| n == d) {
                    visit(sub, order);
                }
            }
        }
    }
    visit(deps, &mut order);
    let mut out = root.to_string();
    for dep in order {
        let (_, text, _) = lookup(dep)?;
        // Every text ends in '\n', so each separator starts on a line of its own.
        out.push_str(&"=".repeat(80));
        out.push_str("\nMSG: ");
        out.push_str(dep);
        out.push('\n');
        out.push_str(text);
    }
    Some(out)
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default, Hash)]
pub struct Time {
    /// Seconds since the epoch.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch.
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
    /// Nanoseconds since the epoch (0 for stamps before it).
    pub fn as_ns(self) -> u64 {
        u64::try_from(self.sec).map_or(0, |s| s * 1_000_000_000 + u64::from(self.nanosec))
    }
}

impl RosMessage for Time {
    const TYPE_NAME: &'static str = "builtin_interfaces/msg/Time";
    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            sec: r.i32()?,
            nanosec: r.u32()?,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// Capture time.
    pub stamp: Time,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

impl RosMessage for Header {
    const TYPE_NAME: &'static str = "std_msgs/msg/Header";
    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            stamp: Time::read(r)?,
            frame_id: r.string()?,
        })
    }
}

/// Reads only `header.stamp` from a payload whose first field is a `std_msgs/Header`
/// (Image, CompressedImage, JointState, PoseStamped; also CompressedVideo, whose first field is
/// its `timestamp`): cheap enough for every received message.
pub fn header_stamp(payload: &[u8]) -> Result<Time> {
    Time::read(&mut CdrReader::new(payload)?)
}

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Image {
    /// Capture stamp and camera frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding, e.g. `bgra8`, `rgb8`.
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

/// `sensor_msgs/msg/JointState`. Arrays are parallel to `name`; map joints by name, not index.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// Sample stamp.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions (rad or m).
    pub position: Vec<f64>,
    /// Velocities (may be empty).
    pub velocity: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
}

impl RosMessage for JointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string_seq(&self.name);
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            name: r.string_seq()?,
            position: r.f64_seq()?,
            velocity: r.f64_seq()?,
            effort: r.f64_seq()?,
        })
    }
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseStamped {
    /// Stamp and reference frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

macro_rules! float_fields {
    ($ty:ident, $name:literal, $($f:ident),+) => {
        impl RosMessage for $ty {
            const TYPE_NAME: &'static str = $name;
            fn write(&self, w: &mut CdrWriter) {
                $(w.f64(self.$f);)+
            }
            fn read(r: &mut CdrReader<'_>) -> Result<Self> {
                Ok(Self { $($f: r.f64()?),+ })
            }
        }
    };
}
float_fields!(Point, "geometry_msgs/msg/Point", x, y, z);
float_fields!(Quaternion, "geometry_msgs/msg/Quaternion", x, y, z, w);

impl RosMessage for Pose {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Pose";
    fn write(&self, w: &mut CdrWriter) {
        self.position.write(w);
        self.orientation.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            position: Point::read(r)?,
            orientation: Quaternion::read(r)?,
        })
    }
}

impl RosMessage for PoseStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.pose.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            pose: Pose::read(r)?,
        })
    }
}

/// `rosgraph_msgs/msg/Clock`: a simulation's time on `/clock`, which nodes follow instead of the
/// wall clock under ROS's `use_sim_time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Clock {
    /// The simulation's time now.
    pub clock: Time,
}

impl RosMessage for Clock {
    const TYPE_NAME: &'static str = "rosgraph_msgs/msg/Clock";
    fn write(&self, w: &mut CdrWriter) {
        self.clock.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            clock: Time::read(r)?,
        })
    }
}
