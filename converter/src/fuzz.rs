//! A coverage-free mutation fuzzer for every reader of the converter, on the stable toolchain:
//! the seed files of the hostile-input corpus (`tests/py/make_corpus.py`: MCAP, ROS 1 bags,
//! rosbag2 sqlite3, and the messages and rig inside them) are mutated — bit flips, interesting
//! bytes, inserts, deletes, splices across seeds, corrupted length fields, truncations — and fed
//! to the MCAP stream reader, the whole-file MCAP reader, the ROS 1 bag reader, the rosbag2
//! sqlite3 reader, the CDR and ROS 1 decoders of every message type, the image path and the rig
//! TOML parser, and whole mutated recordings through a conversion. A panic, or one input taking
//! longer than [`SLOW`], is a finding: the input is saved and the test fails naming it.
//!
//! The test run does a fixed number of iterations per target (seconds in all); a long run:
//!
//! ```sh
//! SCALEDP_FUZZ_ITERS=100000 SCALEDP_FUZZ_SEED=$RANDOM \
//!     cargo test --release -p scaledp-converter fuzz -- --nocapture
//! ```
//!
//! Findings are written to `target/fuzz-findings/` (or `SCALEDP_FUZZ_OUT`); each one fixed
//! becomes a case of the corpus.

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use scaledp_schema::msg::{CompressedImage, Image, JointState, PoseStamped};
use scaledp_schema::RosMessage;

use crate::episode::convert;
use crate::frames::InMemory;
use crate::images::{encode_message, EncodeSpec, ImageView};
use crate::options::ConvertOptions;
use crate::source::{Recording, Serialization, TopicInfo};

/// One input longer than this is a finding (a near-hang).
const SLOW: Duration = Duration::from_secs(10);
/// Iterations per target in the normal test run.
const DEFAULT_ITERS: u64 = 300;

/// xorshift64*: a small seeded generator (the converter has no `rand` dependency).
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub(crate) fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `0..n` (0 for n = 0).
    pub(crate) fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

/// Values that break length fields and counters.
const INTERESTING: [u64; 12] = [
    0,
    1,
    0x7F,
    0x80,
    0xFF,
    0xFFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    1 << 40,
    0x7FFF_FFFF_FFFF_FFFF,
    u64::MAX,
];

/// Mutates `data` with 1 to 4 operations; `other` is spliced from.
pub(crate) fn mutate(data: &mut Vec<u8>, other: &[u8], rng: &mut Rng) {
    for _ in 0..1 + rng.below(4) {
        let len = data.len();
        match rng.below(9) {
            0 => {
                for _ in 0..1 + rng.below(8) {
                    if len > 0 {
                        let i = rng.below(len);
                        data[i] ^= 1 << rng.below(8);
                    }
                }
            }
            1 if len > 0 => {
                let i = rng.below(len);
                data[i] = INTERESTING[rng.below(5)] as u8;
            }
            2 => {
                let at = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                data.splice(at..at, bytes);
            }
            3 if len > 0 => {
                let at = rng.below(len);
                let n = (1 + rng.below(64)).min(len - at);
                data.drain(at..at + n);
            }
            4 if !other.is_empty() => {
                let from = rng.below(other.len());
                let n = (1 + rng.below(4096)).min(other.len() - from);
                let at = rng.below(len + 1);
                let end = (at + n).min(len);
                data.splice(at..end, other[from..from + n].iter().copied());
            }
            5 if len >= 8 => {
                // A length or count field: 4 or 8 bytes, little-endian, often aligned.
                let wide = rng.below(2) == 0;
                let n = if wide { 8 } else { 4 };
                let at = (rng.below(len - n + 1)) & !(rng.below(2) * 3);
                let v = match rng.below(3) {
                    0 => INTERESTING[rng.below(INTERESTING.len())],
                    1 => len as u64 + rng.below(3) as u64,
                    _ => {
                        let mut b = [0u8; 8];
                        b[..n].copy_from_slice(&data[at..at + n]);
                        u64::from_le_bytes(b)
                            .wrapping_add(rng.below(33) as u64)
                            .wrapping_sub(16)
                    }
                };
                data[at..at + n].copy_from_slice(&v.to_le_bytes()[..n]);
            }
            6 if len > 0 => data.truncate(rng.below(len)),
            7 if len > 0 => {
                let at = rng.below(len);
                let n = (1 + rng.below(256)).min(len - at);
                let copy = data[at..at + n].to_vec();
                let to = rng.below(len + 1);
                data.splice(to..to, copy);
            }
            _ if len > 0 => {
                let at = rng.below(len);
                let n = (1 + rng.below(512)).min(len - at);
                data[at..at + n].fill(0);
            }
            _ => data.push(rng.next() as u8),
        }
    }
}

/// Iterations per target: `SCALEDP_FUZZ_ITERS`, else [`DEFAULT_ITERS`].
pub(crate) fn iterations() -> u64 {
    std::env::var("SCALEDP_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(DEFAULT_ITERS)
}

/// The generator's seed: `SCALEDP_FUZZ_SEED`, else fixed (the test run is reproducible).
pub(crate) fn seed() -> u64 {
    std::env::var("SCALEDP_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x05CA_1ED9)
}

/// Where findings are written.
fn findings_dir() -> PathBuf {
    std::env::var_os("SCALEDP_FUZZ_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/fuzz-findings"))
}

/// Runs `iters` mutations of the seeds through `target`; returns one line per finding.
pub(crate) fn run(
    name: &str,
    seeds: &[Vec<u8>],
    iters: u64,
    target: &mut dyn FnMut(&[u8]),
) -> Vec<String> {
    let mut rng = Rng::new(
        seed()
            ^ name
                .bytes()
                .fold(0u64, |h, b| h.rotate_left(5) ^ u64::from(b)),
    );
    let mut findings = Vec::new();
    let t0 = Instant::now();
    for i in 0..iters {
        let k = rng.below(seeds.len());
        let mut data = seeds[k].clone();
        let other = &seeds[rng.below(seeds.len())];
        mutate(&mut data, other, &mut rng);
        let start = Instant::now();
        let outcome = catch_unwind(AssertUnwindSafe(|| target(&data)));
        let took = start.elapsed();
        let problem = match outcome {
            Err(panic) => Some(format!(
                "panic: {}",
                panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_default()
            )),
            Ok(()) if took > SLOW => Some(format!("took {:.1} s", took.as_secs_f64())),
            Ok(()) => None,
        };
        if let Some(problem) = problem {
            let dir = findings_dir();
            let file = dir.join(format!("{name}-{}-{i}.bin", seed()));
            let _ = std::fs::create_dir_all(&dir);
            let _ = std::fs::write(&file, &data);
            findings.push(format!(
                "{name} iteration {i}: {problem} ({})",
                file.display()
            ));
        }
    }
    let s = t0.elapsed().as_secs_f64();
    eprintln!(
        "fuzz {name}: {iters} inputs in {s:.1} s ({:.0}/s), {} findings",
        iters as f64 / s.max(1e-9),
        findings.len()
    );
    findings
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corpus, generated once per test binary.
    fn corpus() -> &'static Path {
        static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
        DIR.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
            let python = std::env::var_os("SCALEDP_PYTHON")
                .map(PathBuf::from)
                .unwrap_or_else(|| root.join(".venv/bin/python"));
            let out = std::process::Command::new(&python)
                .arg(root.join("tests/py/make_corpus.py"))
                .arg(dir.path())
                .args(["--seconds", "1"])
                .output()
                .unwrap_or_else(|e| {
                    panic!("{}: {e} (run scripts/setup-python.sh)", python.display())
                });
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            dir
        })
        .path()
    }

    fn seeds(names: &[&str]) -> Vec<Vec<u8>> {
        names
            .iter()
            .map(|n| std::fs::read(corpus().join(n)).unwrap())
            .collect()
    }

    fn all(_: &TopicInfo) -> bool {
        true
    }

    fn options() -> ConvertOptions {
        ConvertOptions::default().size(16, 12).task("t")
    }

    /// Converts `rec` as read from `path` (rig detected): the result does not matter, only
    /// that it comes.
    fn convert_quietly(path: &Path, rec: &Recording) {
        let _ = convert(path, rec, &InMemory(rec), &options());
    }

    /// A scratch file for inputs only a path can carry.
    fn scratch(ext: &str) -> PathBuf {
        static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
        let dir = DIR.get_or_init(|| tempfile::tempdir().unwrap()).path();
        let thread = format!("{:?}", std::thread::current().id());
        let tag: String = thread.chars().filter(char::is_ascii_digit).collect();
        dir.join(format!("input{tag}.{ext}"))
    }

    fn check(findings: Vec<String>) {
        assert!(findings.is_empty(), "{}", findings.join("\n"));
    }

    #[test]
    fn fuzz_mcap_readers() {
        let seeds = seeds(&[
            "good_standalone.mcap",
            "good_zstd.mcap",
            "good_wobbling_stamps.mcap",
        ]);
        let file = scratch("mcap");
        // With the rig known up front, the one-read path also picks frames to encode as the
        // file streams past.
        let good = corpus().join("good_standalone.mcap");
        let rec = crate::read_mcap(&good, &all).unwrap();
        let with_rig = options().rig(crate::detect::detect(&good, &rec, 10.0).unwrap());
        check(run("mcap", &seeds, iterations(), &mut |data| {
            std::fs::write(&file, data).unwrap();
            // The streaming reader, every payload decoded (deferred tails too).
            let _ = crate::mcap_stream::stream(&file, &mut |_, _, payload, _| {
                let _ = payload.share().with(|b| b.len());
                Ok(true)
            });
            // The whole-file reader, and what is read converted.
            if let Ok(rec) = crate::read_mcap(&file, &all) {
                convert_quietly(&file, &rec);
            }
            // The one-read path of a batch job, frames encoded on the way.
            if let Ok((rec, frames)) = crate::frames::read_mcap_light(&file, &all, Some(&with_rig))
            {
                let _ = convert(&file, &rec, &frames, &with_rig);
            }
        }));
    }

    #[test]
    fn fuzz_ros1_bags() {
        let seeds = seeds(&[
            "good_ros1_none.bag",
            "good_ros1_bz2.bag",
            "good_ros1_lz4.bag",
        ]);
        let file = scratch("bag");
        check(run("ros1", &seeds, iterations(), &mut |data| {
            std::fs::write(&file, data).unwrap();
            if let Ok(rec) = crate::read_ros1_bag(&file, &all) {
                convert_quietly(&file, &rec);
            }
        }));
    }

    #[test]
    fn fuzz_rosbag2_sqlite3() {
        let seeds = seeds(&["good_rosbag2_sqlite3/good_rosbag2_sqlite3.db3"]);
        let file = scratch("db3");
        // Fewer: each input is a SQLite database opened from disk.
        check(run("sqlite3", &seeds, iterations() / 3 + 1, &mut |data| {
            std::fs::write(&file, data).unwrap();
            if let Ok(rec) = crate::read_rosbag2(&file, &all) {
                convert_quietly(&file, &rec);
            }
        }));
    }

    /// Every message of the good recording, by type, as CDR and as ROS 1 (up to 8 of each).
    fn messages() -> BTreeMap<(String, bool), Vec<Vec<u8>>> {
        let mut out: BTreeMap<(String, bool), Vec<Vec<u8>>> = BTreeMap::new();
        let cdr = crate::read_mcap(&corpus().join("good_standalone.mcap"), &all).unwrap();
        let ros1 = crate::read_ros1_bag(&corpus().join("good_ros1_none.bag"), &all).unwrap();
        let compressed = crate::read_mcap(&corpus().join("c_garbage_jpeg.mcap"), &all).unwrap();
        for m in cdr
            .messages
            .iter()
            .chain(&ros1.messages)
            .chain(&compressed.messages)
        {
            let ros1 = m.serialization == Serialization::Ros1;
            let list = out.entry((m.message_type.clone(), ros1)).or_default();
            if list.len() < 8 {
                list.push(m.data.clone());
            }
        }
        out
    }

    #[test]
    fn fuzz_message_decoders() {
        let spec = EncodeSpec {
            width: 16,
            height: 12,
            quality: 80,
            raw: false,
        };
        let path = Path::new("fuzz.mcap");
        let mut findings = Vec::new();
        for ((ty, ros1), seeds) in messages() {
            let ser = if ros1 {
                Serialization::Ros1
            } else {
                Serialization::Cdr
            };
            let name = format!("{}-{ser:?}", ty.rsplit('/').next().unwrap_or_default());
            findings.extend(run(&name, &seeds, iterations(), &mut |data| {
                match ser {
                    Serialization::Cdr => {
                        let _ = scaledp_schema::msg::header_stamp(data);
                        let _ = Image::from_cdr(data);
                        let _ = CompressedImage::from_cdr(data);
                        let _ = JointState::from_cdr(data);
                        let _ = PoseStamped::from_cdr(data);
                        if let Ok(view) = ImageView::from_cdr(data) {
                            let _ = crate::images::resized_rgb(&view, 16, 12);
                        }
                    }
                    Serialization::Ros1 => {
                        let _ = crate::ros1::decode::image(data);
                        let _ = crate::ros1::decode::compressed_image(data);
                        let _ = crate::ros1::decode::joint_state(data);
                        let _ = crate::ros1::decode::pose_stamped(data);
                    }
                }
                if ty.ends_with("Image") {
                    let _ = encode_message(path, "/cam", &ty, 0, ser, data, &spec);
                }
            }));
        }
        // The compressed image path itself: JPEG bytes mutated inside a valid message.
        let jpeg = crate::images::jpeg(
            &crate::images::Rgb {
                width: 24,
                height: 16,
                data: (0..24 * 16 * 3).map(|i| (i * 7) as u8).collect(),
            },
            90,
        )
        .unwrap();
        findings.extend(run("jpeg", &[jpeg], iterations(), &mut |data| {
            let msg = CompressedImage {
                format: "jpeg".into(),
                data: data.to_vec(),
                ..Default::default()
            };
            let _ = encode_message(
                path,
                "/cam",
                "sensor_msgs/msg/CompressedImage",
                0,
                Serialization::Cdr,
                &msg.to_cdr(),
                &spec,
            );
        }));
        check(findings);
    }

    #[test]
    fn fuzz_rig_toml_and_bag_metadata() {
        let rigs: Vec<Vec<u8>> = ["franka_2zed", "bimanual_ur5_3rs"]
            .iter()
            .map(|n| {
                let rig = scaledp_schema::Rig::builtin(n).unwrap();
                toml::to_string(&rig).unwrap().into_bytes()
            })
            .collect();
        let mut findings = run("rig", &rigs, iterations() * 3, &mut |data| {
            let text = String::from_utf8_lossy(data);
            if let Ok(mut rig) = scaledp_schema::Rig::parse(&text, Path::new("rig.toml")) {
                let _ = rig.topics();
                let _ = crate::episode::state_names(&rig, scaledp_schema::ActionSpace::Joints);
                let o = [("wrist".to_string(), "/x".to_string())];
                let _ = crate::detect::override_topics(Path::new("x"), &mut rig, &o);
            }
        });
        let yaml = seeds(&["good_rosbag2_sqlite3/metadata.yaml"]);
        findings.extend(run("metadata.yaml", &yaml, iterations() * 3, &mut |data| {
            let _ = crate::rosbag2::relative_file_paths(&String::from_utf8_lossy(data));
        }));
        check(findings);
    }
}
