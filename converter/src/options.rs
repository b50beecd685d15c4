//! The settings of a conversion: [`ConvertOptions`] for one input (read by the frame reader,
//! the prefetcher, the time series and the episode builder alike) and [`JobOptions`] for a batch
//! job. They live here, below every module that reads them, so the converter's modules import
//! one another in one direction only (inputs → frames → encode → episode → batch).

use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;

use crate::images::EncodeSpec;
use scaledp_codec::Codec;

/// How to convert one input, set with chained setters. Defaults: the rig given, else the one
/// stored in the recording, else one detected; the rig's control rate; 320×240 JPEG at quality
/// 90; a frame staler than 1.5 of its periods invalidates a tick; at most 5 % invalid ticks;
/// header stamps as time; messages up to 0.1 s out of stamp order put back in order; depth
/// kept where the rig has it.
///
/// ```
/// use scaledp_converter::ConvertOptions;
/// let opts = ConvertOptions::default()
///     .size(320, 240)
///     .jpeg_quality(90)
///     .task("put the cup on the plate")
///     .topic_override("wrist", "/camera/wrist/image_raw");
/// # let _ = opts;
/// ```
///
/// The fields are public for the callers that still build the struct literally
/// (`sim/tests/record_convert.rs`); they become private once none does: use the setters.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// Rig to map topics with (else the one stored in the recording, else detected).
    #[doc(hidden)]
    pub rig: Option<Rig>,
    /// Target rate (Hz); the rig's control rate when None.
    #[doc(hidden)]
    pub fps: Option<f64>,
    /// Output image width.
    #[doc(hidden)]
    pub width: u32,
    /// Output image height.
    #[doc(hidden)]
    pub height: u32,
    /// JPEG quality.
    #[doc(hidden)]
    pub jpeg_quality: u8,
    /// A camera frame older than this many of its periods invalidates a tick.
    #[doc(hidden)]
    pub stale_periods: f64,
    /// Largest fraction of invalid ticks an episode may keep.
    #[doc(hidden)]
    pub max_invalid_fraction: f64,
    /// Task when the recording stores none.
    #[doc(hidden)]
    pub task: Option<String>,
    /// Align on log (receive) times instead of header stamps.
    #[doc(hidden)]
    pub use_log_time: bool,
    /// Convert only messages logged in `[start, end)` (ns): one part of a split recording (set
    /// by the batch job).
    #[doc(hidden)]
    pub window_ns: Option<(u64, u64)>,
    /// (name, topic): read camera / arm `name` (or `<arm>_gripper`, `<arm>_command`) from
    /// `topic` instead of the rig's.
    #[doc(hidden)]
    pub topic_overrides: Vec<(String, String)>,
    /// How far back (s) a stamp may lie behind one stored before it on its topic and be put
    /// back in order; further back is a clock jump.
    #[doc(hidden)]
    pub reorder_window_s: f64,
    /// Store cameras as video features in this codec instead of JPEG images.
    #[doc(hidden)]
    pub video: Option<Codec>,
    /// The space of `observation.state` and `action`.
    #[doc(hidden)]
    pub action_space: ActionSpace,
    /// Keep the depth of cameras the rig gives a depth topic.
    #[doc(hidden)]
    pub depth: bool,
}

impl ConvertOptions {
    /// Maps topics with `rig` (default: the rig stored in the recording, else one detected from
    /// message types and joint names).
    pub fn rig(mut self, rig: Rig) -> Self {
        self.rig = Some(rig);
        self
    }
    /// Ticks at `hz` (default: the rig's control rate).
    pub fn fps(mut self, hz: f64) -> Self {
        self.fps = Some(hz);
        self
    }
    /// Stored image size (default 320×240).
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width;
        self.height = height;
        self
    }
    /// JPEG quality of stored images, 1–100 (default 90).
    pub fn jpeg_quality(mut self, quality: u8) -> Self {
        self.jpeg_quality = quality;
        self
    }
    /// A camera frame older than `periods` of its frame periods invalidates a tick (default 1.5).
    pub fn stale_periods(mut self, periods: f64) -> Self {
        self.stale_periods = periods;
        self
    }
    /// Largest fraction of invalid ticks inside an episode (default 0.05); more rejects it.
    pub fn max_invalid_fraction(mut self, fraction: f64) -> Self {
        self.max_invalid_fraction = fraction;
        self
    }
    /// Task instruction for inputs that store none (bags).
    pub fn task(mut self, task: impl Into<String>) -> Self {
        self.task = Some(task.into());
        self
    }
    /// Aligns on log (receive) times instead of header stamps (default false).
    pub fn use_log_time(mut self, yes: bool) -> Self {
        self.use_log_time = yes;
        self
    }
    /// Reads camera or arm `name` (or `<arm>_gripper`, `<arm>_command`) from `topic` instead of
    /// the rig's (repeatable; an unknown name fails the input).
    pub fn topic_override(mut self, name: impl Into<String>, topic: impl Into<String>) -> Self {
        self.topic_overrides.push((name.into(), topic.into()));
        self
    }
    /// Messages stamped up to `seconds` before one stored earlier on their topic are put back
    /// in stamp order and counted (default 0.1); further back is a clock jump.
    pub fn reorder_window(mut self, seconds: f64) -> Self {
        self.reorder_window_s = seconds;
        self
    }
    /// Stores the cameras as LeRobot video features (MP4, one file per camera and file index,
    /// episodes concatenated) encoded with `codec` at LeRobot's settings (yuv420p, a keyframe
    /// every 2 frames, CRF 30), instead of JPEG image features (default: images).
    pub fn video(mut self, codec: Option<Codec>) -> Self {
        self.video = codec;
        self
    }
    /// The space of `observation.state` and `action` (default [`ActionSpace::Tcp`]: 6D TCP
    /// poses by forward kinematics; [`ActionSpace::Joints`]: joint positions), gripper
    /// openings in both.
    pub fn action_space(mut self, space: ActionSpace) -> Self {
        self.action_space = space;
        self
    }
    /// Keeps each camera's registered depth, when the rig gives it a depth topic, as the
    /// feature `observation.depth.<camera>` (default true; false leaves depth out).
    pub fn depth(mut self, yes: bool) -> Self {
        self.depth = yes;
        self
    }
    /// Whether a message logged at `log_ns` is inside the window converted.
    pub(crate) fn in_window(&self, log_ns: u64) -> bool {
        self.window_ns.is_none_or(|(a, b)| (a..b).contains(&log_ns))
    }
    /// The reorder window in ns.
    pub(crate) fn reorder_window_ns(&self) -> u64 {
        (self.reorder_window_s.max(0.0) * 1e9).min(u64::MAX as f64) as u64
    }
    /// Output size and quality of frames.
    pub(crate) fn encode_spec(&self) -> EncodeSpec {
        EncodeSpec {
            width: self.width,
            height: self.height,
            quality: self.jpeg_quality,
            raw: self.video.is_some(),
        }
    }
}

impl Default for ConvertOptions {
    fn default() -> Self {
        Self {
            rig: None,
            fps: None,
            width: 320,
            height: 240,
            jpeg_quality: 90,
            stale_periods: scaledp_align::DEFAULT_STALE_PERIODS,
            max_invalid_fraction: scaledp_align::DEFAULT_MAX_INVALID_FRACTION,
            task: None,
            use_log_time: false,
            window_ns: None,
            topic_overrides: Vec::new(),
            reorder_window_s: scaledp_align::DEFAULT_REORDER_WINDOW_S,
            video: None,
            action_space: ActionSpace::Tcp,
            depth: true,
        }
    }
}

/// What a job does with an episode recorded without a success or failure label (`stop`
/// rather than a label, an unattended or timed recording, a foreign bag: none has one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Unlabeled {
    /// No choice made: [`crate::run`] refuses the job, naming the unlabelled inputs, before it
    /// converts anything (an input it could not read a label from ahead fails alone).
    #[default]
    Refuse,
    /// Converted, stored with label `unlabeled` (`scaledp/label` in `meta/episodes/`).
    Keep,
    /// Left out, reported as skipped.
    Skip,
}

/// Settings of a conversion job, set with chained setters. Defaults: [`ConvertOptions`]'s
/// defaults, no overwrite, no shard, one job per core, data files of 100 MiB, `failure`
/// episodes skipped, unlabelled ones refused ([`Unlabeled::Refuse`]), no split.
///
/// ```no_run
/// use scaledp_converter::{ConvertOptions, JobOptions};
/// let opts = JobOptions::default()
///     .convert(ConvertOptions::default().task("stack the cups"))
///     .jobs(4);
/// let results = scaledp_converter::run(&["demos/episode_000000.mcap".into()], "ds".as_ref(), &opts, &|_| {})?;
/// # Ok::<(), scaledp_converter::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct JobOptions {
    pub(crate) convert: ConvertOptions,
    pub(crate) overwrite: bool,
    pub(crate) shard: Option<(usize, usize)>,
    pub(crate) jobs: usize,
    pub(crate) file_size_mib: u64,
    pub(crate) include_failures: bool,
    pub(crate) unlabeled: Unlabeled,
    pub(crate) split_gap_s: Option<f64>,
    pub(crate) work_dir: Option<std::path::PathBuf>,
}

impl Default for JobOptions {
    fn default() -> Self {
        Self {
            convert: ConvertOptions::default(),
            overwrite: false,
            shard: None,
            jobs: std::thread::available_parallelism().map_or(2, usize::from),
            file_size_mib: 100,
            include_failures: false,
            unlabeled: Unlabeled::Refuse,
            split_gap_s: None,
            work_dir: None,
        }
    }
}

impl JobOptions {
    /// Per-episode conversion settings.
    pub fn convert(mut self, convert: ConvertOptions) -> Self {
        self.convert = convert;
        self
    }
    /// Reconvert inputs already in the dataset: the dataset is rebuilt from scratch.
    pub fn overwrite(mut self, yes: bool) -> Self {
        self.overwrite = yes;
        self
    }
    /// Convert only slice `i` of `n` of the sorted inputs (contiguous, so merging the shards in
    /// order equals one run); `run` refuses `i >= n`.
    pub fn shard(mut self, i: usize, n: usize) -> Self {
        self.shard = Some((i, n));
        self
    }
    /// Episodes converted at once (each holds its recording in memory; at least 1).
    pub fn jobs(mut self, n: usize) -> Self {
        self.jobs = n.max(1);
        self
    }
    /// Data file size target in MiB (LeRobot's `data_files_size_in_mb`, which LeRobot itself
    /// measures in MiB): a file is closed once it reaches it.
    pub fn file_size_mib(mut self, mib: u64) -> Self {
        self.file_size_mib = mib;
        self
    }
    /// Also convert episodes whose recorded outcome is `failure`.
    pub fn include_failures(mut self, yes: bool) -> Self {
        self.include_failures = yes;
        self
    }
    /// What to do with episodes recorded without a label (see [`Unlabeled`]).
    pub fn unlabeled(mut self, policy: Unlabeled) -> Self {
        self.unlabeled = policy;
        self
    }
    /// Split an input into several episodes wherever no message was logged for `seconds`.
    pub fn split_gap(mut self, seconds: f64) -> Self {
        self.split_gap_s = Some(seconds);
        self
    }
    /// Where inputs from object storage that are read whole (bags, `.db3`, rosbag2
    /// directories) are downloaded, and where the working copy of a dataset written to object
    /// storage lives (default: the system's temporary directory).
    pub fn work_dir(mut self, dir: impl Into<std::path::PathBuf>) -> Self {
        self.work_dir = Some(dir.into());
        self
    }
    /// The work directory in use.
    pub(crate) fn work_dir_or_temp(&self) -> std::path::PathBuf {
        self.work_dir.clone().unwrap_or_else(std::env::temp_dir)
    }
}
