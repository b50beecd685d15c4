//! What every message builds on: the [`RosMessage`] trait, [`Time`], [`Header`] (and reading
//! only its stamp), and `rosgraph_msgs/Clock`.

use super::texts::definition;
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
/// (Image, CompressedImage, JointState, PoseStamped, CameraInfo; also CompressedVideo, whose
/// first field is its `timestamp`): cheap enough for every received message.
pub fn header_stamp(payload: &[u8]) -> Result<Time> {
    Time::read(&mut CdrReader::new(payload)?)
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
