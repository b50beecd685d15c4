//! The reference load of `scaledp bench record` and the rig that records it: two ZED cameras
//! (1920×1080 bgra8 at 30 Hz, registered depth 32FC1), three RealSense cameras (640×480 rgb8
//! at 30 Hz, aligned depth 16UC1, both `camera_info`s), two arms' joint states at 500 Hz and
//! `/tf` at 100 Hz — about 1.1 GB/s. `--load F` multiplies every image's pixel count by F
//! (width and height by √F, kept even), rates unchanged.

use scaledp_schema::Rig;

/// Camera frame rate (Hz).
pub const FPS: f64 = 30.0;
/// Joint state rate of each arm (Hz).
pub const JOINT_HZ: f64 = 500.0;
/// `/tf` rate (Hz).
pub const TF_HZ: f64 = 100.0;

/// One camera of the load.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Name in the rig.
    pub name: String,
    /// `zed` or `realsense`.
    pub model: &'static str,
    /// Colour topic.
    pub topic: String,
    /// Colour encoding (`bgra8`, `rgb8`).
    pub encoding: &'static str,
    /// Width and height of colour and depth.
    pub size: (u32, u32),
    /// Depth topic.
    pub depth_topic: String,
    /// Depth encoding (`32FC1` metres, `16UC1` millimetres).
    pub depth_encoding: &'static str,
    /// The colour and depth `camera_info` topics, for cameras that publish them.
    pub info_topics: Option<(String, String)>,
}

impl Camera {
    /// Bytes per colour pixel.
    pub fn colour_bpp(&self) -> u32 {
        if self.encoding == "bgra8" {
            4
        } else {
            3
        }
    }
    /// Bytes per depth pixel.
    pub fn depth_bpp(&self) -> u32 {
        if self.depth_encoding == "32FC1" {
            4
        } else {
            2
        }
    }
}

/// The load: cameras, arms, `/tf`.
#[derive(Debug, Clone, PartialEq)]
pub struct Load {
    /// The fraction of the reference's image bytes.
    pub fraction: f64,
    /// The cameras.
    pub cameras: Vec<Camera>,
    /// Each arm's name and joint state topic.
    pub arms: Vec<(String, String)>,
}

/// A topic of the load with its nominal rate and payload size.
#[derive(Debug, Clone, PartialEq)]
pub struct Offered {
    /// ROS 2 topic.
    pub topic: String,
    /// Messages per second offered.
    pub rate_hz: f64,
    /// Payload bytes per message, about (images exactly up to their header's frame id).
    pub bytes: u64,
}

/// `v × s` rounded to an even number, at least 2.
fn scaled(v: u32, s: f64) -> u32 {
    ((f64::from(v) * s / 2.0).round() as u32).max(1) * 2
}

/// The reference load at `fraction` of its image bytes.
pub fn reference(fraction: f64) -> Load {
    let s = fraction.sqrt();
    let zed = |side: &str| Camera {
        name: format!("zed_{side}"),
        model: "zed",
        topic: format!("/zed_{side}/zed_node/rgb/color/rect/image"),
        encoding: "bgra8",
        size: (scaled(1920, s), scaled(1080, s)),
        depth_topic: format!("/zed_{side}/zed_node/depth/depth_registered"),
        depth_encoding: "32FC1",
        info_topics: None,
    };
    let realsense = |ns: &str| Camera {
        name: ns.into(),
        model: "realsense",
        topic: format!("/{ns}/camera/color/image_raw"),
        encoding: "rgb8",
        size: (scaled(640, s), scaled(480, s)),
        depth_topic: format!("/{ns}/camera/aligned_depth_to_color/image_raw"),
        depth_encoding: "16UC1",
        info_topics: Some((
            format!("/{ns}/camera/color/camera_info"),
            format!("/{ns}/camera/aligned_depth_to_color/camera_info"),
        )),
    };
    Load {
        fraction,
        cameras: vec![
            zed("left"),
            zed("right"),
            realsense("cam_high"),
            realsense("cam_left_wrist"),
            realsense("cam_right_wrist"),
        ],
        arms: ["left", "right"]
            .iter()
            .map(|a| (a.to_string(), format!("/{a}/joint_states")))
            .collect(),
    }
}

/// Joint names of arm `arm`.
pub fn joint_names(arm: &str) -> Vec<String> {
    [
        "shoulder_pan",
        "shoulder_lift",
        "elbow",
        "wrist_1",
        "wrist_2",
        "wrist_3",
    ]
    .iter()
    .map(|j| format!("{arm}_{j}_joint"))
    .collect()
}

/// Bytes of a `sensor_msgs/CameraInfo` payload with five distortion coefficients, about.
const CAMERA_INFO_BYTES: u64 = 400;
/// Bytes of a `JointState` payload of six joints with positions, velocities and efforts, about.
const JOINT_STATE_BYTES: u64 = 400;
/// Bytes of the `/tf` message (one transform per joint of both arms), about.
const TF_BYTES: u64 = 1300;

impl Load {
    /// Every topic with its rate and payload size, in rig order.
    pub fn offered(&self) -> Vec<Offered> {
        let mut v = Vec::new();
        let topic = |t: &str, rate_hz: f64, bytes: u64| Offered {
            topic: t.to_string(),
            rate_hz,
            bytes,
        };
        for c in &self.cameras {
            let px = u64::from(c.size.0) * u64::from(c.size.1);
            v.push(topic(&c.topic, FPS, px * u64::from(c.colour_bpp())));
            v.push(topic(&c.depth_topic, FPS, px * u64::from(c.depth_bpp())));
            if let Some((ci, di)) = &c.info_topics {
                v.push(topic(ci, FPS, CAMERA_INFO_BYTES));
                v.push(topic(di, FPS, CAMERA_INFO_BYTES));
            }
        }
        for (_, t) in &self.arms {
            v.push(topic(t, JOINT_HZ, JOINT_STATE_BYTES));
        }
        v.push(topic("/tf", TF_HZ, TF_BYTES));
        v
    }

    /// Payload bytes per second offered.
    pub fn offered_bytes_per_s(&self) -> f64 {
        self.offered()
            .iter()
            .map(|o| o.rate_hz * o.bytes as f64)
            .sum()
    }

    /// The rig that records the load, as TOML.
    pub fn rig_toml(&self) -> String {
        let mut t = format!(
            "# The reference load of `scaledp bench record` at {} of its image bytes.\n\
             name = \"bench_soak\"\ncontrol_rate_hz = 10.0\n",
            self.fraction
        );
        for (name, topic) in &self.arms {
            let joints: Vec<String> = joint_names(name)
                .iter()
                .map(|j| format!("\"{j}\""))
                .collect();
            t.push_str(&format!(
                "\n[[arm]]\nname = \"{name}\"\nmodel = \"ur5e\"\njoint_state_topic = \"{topic}\"\n\
                 joint_names = [{}]\nrate_hz = {JOINT_HZ:.1}\n",
                joints.join(", ")
            ));
        }
        for c in &self.cameras {
            t.push_str(&format!(
                "\n[[camera]]\nname = \"{}\"\ntopic = \"{}\"\nmodel = \"{}\"\nwidth = {}\n\
                 height = {}\nfps = {FPS:.1}\n",
                c.name, c.topic, c.model, c.size.0, c.size.1
            ));
            if let Some((ci, _)) = &c.info_topics {
                t.push_str(&format!("camera_info_topic = \"{ci}\"\n"));
            }
            t.push_str(&format!(
                "\n[camera.depth]\ntopic = \"{}\"\nencoding = \"{}\"\n",
                c.depth_topic, c.depth_encoding
            ));
            if let Some((_, di)) = &c.info_topics {
                t.push_str(&format!("camera_info_topic = \"{di}\"\n"));
            }
        }
        t.push_str(&format!("\n[tf]\nstatic = false\nrate_hz = {TF_HZ:.1}\n"));
        t
    }

    /// The rig, parsed (what the recorder is given).
    pub fn rig(&self) -> Result<Rig, scaledp_schema::Error> {
        Rig::parse(&self.rig_toml(), std::path::Path::new("bench_soak.toml"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_is_about_1_1_gb_per_second_and_its_rig_records_every_topic() {
        let full = reference(1.0);
        assert_eq!(full.cameras[0].size, (1920, 1080));
        assert_eq!(full.cameras[2].size, (640, 480));
        // 2 × 1920×1080 × (4 + 4) B + 3 × 640×480 × (3 + 2) B, 30 times a second.
        let images = 30.0 * (2.0 * 1920.0 * 1080.0 * 8.0 + 3.0 * 640.0 * 480.0 * 5.0);
        let total = full.offered_bytes_per_s();
        assert!(total >= images && total < images * 1.001, "{total}");
        let rig = full.rig().expect("the soak rig parses");
        let mut recorded: Vec<String> = rig.topics().into_iter().map(|t| t.topic).collect();
        let mut offered: Vec<String> = full.offered().into_iter().map(|o| o.topic).collect();
        recorded.sort();
        offered.sort();
        assert_eq!(recorded, offered);

        let small = reference(0.01);
        assert_eq!(small.cameras[0].size, (192, 108));
        assert_eq!(small.cameras[2].size, (64, 48));
        let ratio = small.offered_bytes_per_s() / total;
        assert!((0.009..0.011).contains(&ratio), "{ratio}");
    }
}
