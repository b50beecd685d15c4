//! ROS 1 serialized messages → the `scaledp_schema` types.
//!
//! ROS 1 serialization is little-endian with no alignment, padding or encapsulation header;
//! strings are a `u32` length and the bytes (no NUL), arrays a `u32` count and the elements, and
//! `std_msgs/Header` is `u32 seq`, `time stamp` (`u32` sec, `u32` nsec), `string frame_id` (the
//! seq is dropped). Every length is checked against the bytes that remain before anything is
//! allocated, and a payload must be consumed exactly (left-over bytes mean a different type).

use scaledp_schema::msg::{
    CameraInfo, CompressedImage, Header, Image, JointState, Point, Pose, PoseStamped, Quaternion,
    RegionOfInterest, Time,
};

/// A ROS 1 payload that is not the message it should be: truncated, a length beyond the bytes
/// left, bytes left over (another type), text that is not UTF-8.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bad ROS 1 message at byte {offset}: {reason}")]
pub struct DecodeError {
    /// Byte offset in the payload.
    pub offset: usize,
    /// What is wrong.
    pub reason: String,
}

/// Kept for callers that report errors as text.
impl From<DecodeError> for String {
    fn from(e: DecodeError) -> Self {
        e.to_string()
    }
}

type Result<T> = std::result::Result<T, DecodeError>;

/// Decodes a ROS 1 `sensor_msgs/Image`.
pub fn image(data: &[u8]) -> Result<Image> {
    whole(data, |r| {
        Ok(Image {
            header: r.header()?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?,
            is_bigendian: r.u8()?,
            step: r.u32()?,
            data: r.bytes()?.to_vec(),
        })
    })
}

/// Decodes a ROS 1 `sensor_msgs/CompressedImage`.
pub fn compressed_image(data: &[u8]) -> Result<CompressedImage> {
    whole(data, |r| {
        Ok(CompressedImage {
            header: r.header()?,
            format: r.string()?,
            data: r.bytes()?.to_vec(),
        })
    })
}

/// Decodes a ROS 1 `sensor_msgs/JointState`.
pub fn joint_state(data: &[u8]) -> Result<JointState> {
    whole(data, |r| {
        Ok(JointState {
            header: r.header()?,
            name: r.string_seq()?,
            position: r.f64_seq()?,
            velocity: r.f64_seq()?,
            effort: r.f64_seq()?,
        })
    })
}

/// Decodes a ROS 1 `geometry_msgs/PoseStamped`.
pub fn pose_stamped(data: &[u8]) -> Result<PoseStamped> {
    whole(data, |r| {
        Ok(PoseStamped {
            header: r.header()?,
            pose: Pose {
                position: Point {
                    x: r.f64()?,
                    y: r.f64()?,
                    z: r.f64()?,
                },
                orientation: Quaternion {
                    x: r.f64()?,
                    y: r.f64()?,
                    z: r.f64()?,
                    w: r.f64()?,
                },
            },
        })
    })
}

/// Runs `f` on a reader over `data` and requires it to consume every byte.
/// Decodes a ROS 1 `sensor_msgs/CameraInfo` (`D`, `K`, `R`, `P` in capitals there).
pub fn camera_info(data: &[u8]) -> Result<CameraInfo> {
    whole(data, |r| {
        let header = r.header()?;
        let (height, width) = (r.u32()?, r.u32()?);
        let distortion_model = r.string()?;
        let d = r.f64_seq()?;
        let mut k = [0.0; 9];
        let mut rot = [0.0; 9];
        let mut p = [0.0; 12];
        for v in k.iter_mut().chain(rot.iter_mut()).chain(p.iter_mut()) {
            *v = r.f64()?;
        }
        let (binning_x, binning_y) = (r.u32()?, r.u32()?);
        let roi = RegionOfInterest {
            x_offset: r.u32()?,
            y_offset: r.u32()?,
            height: r.u32()?,
            width: r.u32()?,
            do_rectify: r.u8()? != 0,
        };
        Ok(CameraInfo {
            header,
            height,
            width,
            distortion_model,
            d,
            k,
            r: rot,
            p,
            binning_x,
            binning_y,
            roi,
        })
    })
}

fn whole<T>(data: &[u8], f: impl FnOnce(&mut Reader<'_>) -> Result<T>) -> Result<T> {
    let mut r = Reader { buf: data, pos: 0 };
    let value = f(&mut r)?;
    match r.left() {
        0 => Ok(value),
        n => Err(r.err(format!(
            "{n} bytes left over after the message (wrong type?)"
        ))),
    }
}

/// A bounds-checked little-endian reader.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn left(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn err(&self, reason: String) -> DecodeError {
        DecodeError {
            offset: self.pos,
            reason,
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.left() {
            return Err(self.err(format!(
                "{what} needs {n} bytes but only {} remain (truncated or wrong type)",
                self.left()
            )));
        }
        let out = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let b = self.take(N, what)?;
        b.try_into()
            .map_err(|_| self.err(format!("{what}: short read")))
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.array::<1>("uint8")?[0])
    }

    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array("uint32")?))
    }

    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array("float64")?))
    }

    /// A `u32` count of elements of `size` bytes each, checked against the bytes that remain.
    fn count(&mut self, size: usize, what: &str) -> Result<usize> {
        let n = self.u32()? as usize;
        if n.checked_mul(size).is_none_or(|bytes| bytes > self.left()) {
            return Err(self.err(format!(
                "{what} of {n} elements exceeds the {} bytes that remain",
                self.left()
            )));
        }
        Ok(n)
    }

    fn bytes(&mut self) -> Result<&'a [u8]> {
        let n = self.count(1, "byte array")?;
        self.take(n, "byte array")
    }

    fn string(&mut self) -> Result<String> {
        let at = self.pos;
        let n = self.count(1, "string")?;
        let b = self.take(n, "string")?;
        String::from_utf8(b.to_vec()).map_err(|_| DecodeError {
            offset: at,
            reason: "string is not UTF-8".into(),
        })
    }

    fn string_seq(&mut self) -> Result<Vec<String>> {
        // Each string takes at least its 4-byte length.
        let n = self.count(4, "string array")?;
        (0..n).map(|_| self.string()).collect()
    }

    fn f64_seq(&mut self) -> Result<Vec<f64>> {
        let n = self.count(8, "float64 array")?;
        (0..n).map(|_| self.f64()).collect()
    }

    fn header(&mut self) -> Result<Header> {
        let _seq = self.u32()?;
        let sec = self.u32()?;
        let nanosec = self.u32()?;
        let sec = i32::try_from(sec)
            .map_err(|_| self.err(format!("header stamp seconds {sec} beyond 2038")))?;
        Ok(Header {
            stamp: Time { sec, nanosec },
            frame_id: self.string()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ROS 1 writer for the tests.
    #[derive(Default)]
    struct W(Vec<u8>);
    impl W {
        fn u32(&mut self, v: u32) -> &mut Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        fn f64(&mut self, v: f64) -> &mut Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        fn string(&mut self, s: &str) -> &mut Self {
            self.u32(s.len() as u32);
            self.0.extend_from_slice(s.as_bytes());
            self
        }
        fn header(&mut self, seq: u32, sec: u32, nsec: u32, frame: &str) -> &mut Self {
            self.u32(seq).u32(sec).u32(nsec).string(frame)
        }
    }

    fn image_bytes() -> Vec<u8> {
        let mut w = W::default();
        w.header(7, 1_700_000_000, 123, "cam")
            .u32(2)
            .u32(3)
            .string("bgra8");
        w.0.push(0);
        w.u32(12).u32(24);
        w.0.extend(0..24u8);
        w.0
    }

    fn joint_bytes() -> Vec<u8> {
        let mut w = W::default();
        w.header(1, 5, 6, "")
            .u32(2)
            .string("fr3_joint1")
            .string("fr3_joint2");
        w.u32(2).f64(0.5).f64(-1.25).u32(0).u32(1).f64(3.0);
        w.0
    }

    fn pose_bytes() -> Vec<u8> {
        let mut w = W::default();
        w.header(0, 1, 2, "world");
        for v in [0.1, -0.2, 0.3, 0.0, 0.0, 0.6, 0.8] {
            w.f64(v);
        }
        w.0
    }

    fn compressed_bytes() -> Vec<u8> {
        let mut w = W::default();
        w.header(3, 4, 5, "cam").string("jpeg").u32(4);
        w.0.extend([255, 216, 255, 217]);
        w.0
    }

    #[test]
    fn decodes_valid_payloads() {
        let img = image(&image_bytes()).unwrap();
        assert_eq!(
            img.header.stamp,
            Time {
                sec: 1_700_000_000,
                nanosec: 123
            }
        );
        assert_eq!(img.header.frame_id, "cam");
        assert_eq!(
            (img.height, img.width, img.step, img.is_bigendian),
            (2, 3, 12, 0)
        );
        assert_eq!(img.encoding, "bgra8");
        assert_eq!(img.data, (0..24u8).collect::<Vec<_>>());

        let js = joint_state(&joint_bytes()).unwrap();
        assert_eq!(js.name, ["fr3_joint1", "fr3_joint2"]);
        assert_eq!(js.position, [0.5, -1.25]);
        assert!(js.velocity.is_empty());
        assert_eq!(js.effort, [3.0]);

        let p = pose_stamped(&pose_bytes()).unwrap();
        assert_eq!(p.header.frame_id, "world");
        assert_eq!(
            p.pose.position,
            Point {
                x: 0.1,
                y: -0.2,
                z: 0.3
            }
        );
        assert_eq!(
            p.pose.orientation,
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.6,
                w: 0.8
            }
        );

        let c = compressed_image(&compressed_bytes()).unwrap();
        assert_eq!(
            (c.format.as_str(), c.data.as_slice()),
            ("jpeg", &[255, 216, 255, 217][..])
        );
    }

    #[test]
    fn every_prefix_and_any_extra_byte_is_an_error() {
        type Decoder = fn(&[u8]) -> Result<()>;
        let cases: [(Vec<u8>, Decoder); 4] = [
            (image_bytes(), |d| image(d).map(drop)),
            (joint_bytes(), |d| joint_state(d).map(drop)),
            (pose_bytes(), |d| pose_stamped(d).map(drop)),
            (compressed_bytes(), |d| compressed_image(d).map(drop)),
        ];
        for (bytes, decode) in cases {
            assert!(decode(&bytes).is_ok());
            for n in 0..bytes.len() {
                assert!(decode(&bytes[..n]).is_err(), "prefix of {n} bytes decoded");
            }
            let mut longer = bytes.clone();
            longer.push(0);
            let e = decode(&longer).unwrap_err();
            assert!(
                e.reason.contains("left over") && e.offset == bytes.len(),
                "{e}"
            );
        }
    }

    #[test]
    fn huge_lengths_are_errors_not_allocations() {
        // frame_id claiming 4 GiB.
        let mut w = W::default();
        w.u32(0).u32(1).u32(2).u32(u32::MAX);
        assert!(image(&w.0).unwrap_err().reason.contains("exceeds"));
        // A joint name array claiming 2^32-1 strings, and a float array claiming 2^31 elements.
        let mut w = W::default();
        w.header(0, 1, 2, "").u32(u32::MAX);
        assert!(joint_state(&w.0).unwrap_err().reason.contains("exceeds"));
        let mut w = W::default();
        w.header(0, 1, 2, "").u32(0).u32(1 << 31).f64(1.0);
        assert!(joint_state(&w.0).unwrap_err().reason.contains("exceeds"));
        // Image data claiming more than is there.
        let mut bytes = image_bytes();
        let n = bytes.len();
        bytes[n - 28..n - 24].copy_from_slice(&25u32.to_le_bytes());
        assert!(image(&bytes).is_err());
        // Stamps past 2038 do not fit builtin_interfaces/Time.
        let mut w = W::default();
        w.header(0, u32::MAX, 0, "").string("jpeg").u32(0);
        assert!(compressed_image(&w.0).unwrap_err().reason.contains("2038"));
    }

    #[test]
    fn invalid_utf8_is_an_error() {
        let mut w = W::default();
        w.header(0, 1, 2, "").string("jpeg").u32(0);
        let at = 4 + 8 + 4 + 4; // seq, stamp, empty frame_id, format length
        w.0[at] = 0xff;
        let e = compressed_image(&w.0).unwrap_err();
        assert!(e.reason.contains("UTF-8") && e.offset == at - 4, "{e}");
    }
}
