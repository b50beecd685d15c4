//! What the recorder notices in a camera's streams while it writes them, without judging
//! (the session verdict and the converter do): depth in an encoding the rig does not declare,
//! and a `camera_info` whose size is not the size of the images it describes. Each is recorded
//! as it is; the recorder warns once per topic and notes it in every episode it happens in.

use scaledp_schema::msg::{camera_info_size, image_layout};
use scaledp_schema::rig::{Rig, TopicSpec};

/// What to look at on one topic.
#[derive(Debug, Clone)]
enum Rule {
    /// Nothing.
    None,
    /// Raw images: remember their size; for depth, the encoding the rig declares.
    Image {
        depth_encoding: Option<&'static str>,
    },
    /// A `camera_info` describing the images of topic `images` (their declared size first).
    Info { images: usize, declared: (u32, u32) },
}

/// The checks of one session.
#[derive(Debug)]
pub(crate) struct Checks {
    rules: Vec<Rule>,
    topics: Vec<String>,
    /// Per topic: the latest image size seen, (height, width).
    sizes: Vec<Option<(u32, u32)>>,
    /// Per topic: already warned in the log.
    warned: Vec<bool>,
}

impl Checks {
    /// The rules for `rig`'s cameras; `topics` is the recorder's topic list (the rig's first).
    pub fn new(rig: &Rig, topics: &[TopicSpec]) -> Self {
        let index = |t: &str| topics.iter().position(|s| s.topic == t);
        let mut rules = vec![Rule::None; topics.len()];
        for c in &rig.cameras {
            let raw = !c.compressed && c.video_codec().is_none();
            let color = index(&c.topic);
            if let (Some(i), true) = (color, raw) {
                rules[i] = Rule::Image {
                    depth_encoding: None,
                };
            }
            let depth = c
                .depth
                .as_ref()
                .filter(|d| !d.compressed)
                .and_then(|d| Some((index(&d.topic)?, d.encoding.as_str())));
            if let Some((i, enc)) = depth {
                rules[i] = Rule::Image {
                    depth_encoding: Some(enc),
                };
            }
            let declared = (c.height, c.width);
            let infos = [
                (c.camera_info_topic.as_deref(), color),
                (
                    c.depth
                        .as_ref()
                        .and_then(|d| d.camera_info_topic.as_deref()),
                    c.depth.as_ref().and_then(|d| index(&d.topic)),
                ),
            ];
            for (info, images) in infos {
                if let (Some(i), Some(images)) = (info.and_then(index), images) {
                    rules[i] = Rule::Info { images, declared };
                }
            }
        }
        Self {
            topics: topics.iter().map(|t| t.topic.clone()).collect(),
            sizes: vec![None; topics.len()],
            warned: vec![false; topics.len()],
            rules,
        }
    }

    /// Looks at one message of topic number `topic`: the problem in one line, if any (logged
    /// the first time only; the caller notes it in the episode).
    pub fn inspect(&mut self, topic: usize, payload: &[u8]) -> Option<String> {
        let problem = match self.rules.get(topic)? {
            Rule::None => None,
            Rule::Image { depth_encoding } => {
                let layout = image_layout(payload).ok()?;
                self.sizes[topic] = Some((layout.height, layout.width));
                depth_encoding.filter(|e| *e != layout.encoding).map(|e| {
                    format!(
                        "{}: depth in {}, the rig declares {e}",
                        self.topics[topic], layout.encoding
                    )
                })
            }
            Rule::Info { images, declared } => {
                let (h, w) = camera_info_size(payload).ok()?;
                let (want, seen) = match self.sizes[*images] {
                    Some(s) => (s, "the images on"),
                    None => (*declared, "the rig declares for"),
                };
                ((h, w) != want).then(|| {
                    format!(
                        "{}: camera_info is {w}×{h}, {seen} {} are {}×{}",
                        self.topics[topic], self.topics[*images], want.1, want.0
                    )
                })
            }
        }?;
        if !std::mem::replace(&mut self.warned[topic], true) {
            tracing::warn!("{problem} (recorded as it is)");
        }
        Some(problem)
    }

    /// Follows a topic added mid-session (nothing to check on it).
    pub fn push_topic(&mut self, topic: &str) {
        self.rules.push(Rule::None);
        self.topics.push(topic.to_string());
        self.sizes.push(None);
        self.warned.push(false);
    }
}

#[cfg(test)]
mod tests {
    use scaledp_schema::msg::{CameraInfo, Header, Image};
    use scaledp_schema::RosMessage;

    use super::*;

    fn image(w: u32, h: u32, encoding: &str) -> Vec<u8> {
        Image {
            header: Header::default(),
            height: h,
            width: w,
            encoding: encoding.into(),
            is_bigendian: 0,
            step: w * 4,
            data: vec![0; (w * h * 4) as usize],
        }
        .to_cdr()
    }

    #[test]
    fn wrong_depth_encodings_and_camera_info_sizes_are_named() {
        let rig = Rig::builtin("franka_2zed").unwrap();
        let topics = rig.topics();
        let at = |t: &str| topics.iter().position(|s| s.topic.ends_with(t)).unwrap();
        let mut checks = Checks::new(&rig, &topics);
        let (color, depth) = (0, at("zed_front/zed_node/depth/depth_registered"));
        let info = at("zed_front/zed_node/rgb/color/rect/camera_info");
        let info_cdr =
            |w, h| CameraInfo::pinhole(Header::default(), w, h, 500.0, 1.0, 1.0).to_cdr();
        // Before any image: the declared 1280×720.
        assert_eq!(checks.inspect(info, &info_cdr(1280, 720)), None);
        assert_eq!(checks.inspect(color, &image(64, 48, "bgra8")), None);
        let e = checks.inspect(info, &info_cdr(1280, 720)).unwrap();
        assert_eq!(
            e,
            "/zed_front/zed_node/rgb/color/rect/camera_info: camera_info is 1280×720, the images on /zed_front/zed_node/rgb/color/rect/image are 64×48"
        );
        assert_eq!(checks.inspect(info, &info_cdr(64, 48)), None);
        assert_eq!(checks.inspect(depth, &image(64, 48, "32FC1")), None);
        let e = checks.inspect(depth, &image(64, 48, "16UC1")).unwrap();
        assert!(e.ends_with("depth in 16UC1, the rig declares 32FC1"), "{e}");
        // Garbage is not a problem to report (the converter judges it), nor a panic.
        assert_eq!(checks.inspect(depth, &[1, 2, 3]), None);
        assert_eq!(checks.inspect(99, &[]), None);
    }
}
