//! What a PATH given to `scaledp view` is: decided from the path alone (and a file's first
//! bytes), before anything is opened for writing or a viewer is spawned.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// A kind of input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// An MCAP file: our recordings (`episode_*.mcap`, also a `.partial` one) or any ros2 MCAP.
    Mcap,
    /// A rosbag2 directory (with `metadata.yaml`) or `.db3` file.
    Rosbag2,
    /// A ROS 1 bag (format 2.0).
    Ros1Bag,
    /// A LeRobot v3.0 dataset: a directory with `meta/info.json`, or `s3://bucket/prefix`.
    Dataset,
    /// A directory of recordings and bags (each shown as one episode).
    Directory,
}

const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
const ROSBAG_MAGIC: &[u8] = b"#ROSBAG V2.0";
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

fn sniff(path: &Path) -> Option<InputKind> {
    let mut head = [0u8; 16];
    let mut f = std::fs::File::open(path).ok()?;
    let n = f.read(&mut head).ok()?;
    let head = &head[..n];
    if head.starts_with(MCAP_MAGIC) {
        Some(InputKind::Mcap)
    } else if head.starts_with(ROSBAG_MAGIC) {
        Some(InputKind::Ros1Bag)
    } else if head.starts_with(SQLITE_MAGIC) {
        Some(InputKind::Rosbag2)
    } else {
        None
    }
}

/// The kind of `location` (a path, or an `s3://` URL).
pub fn classify(location: &str) -> Result<InputKind> {
    if location.starts_with("s3://") {
        return Ok(InputKind::Dataset);
    }
    let path = Path::new(location);
    let unknown = |reason: &str| Error::UnknownInput {
        path: PathBuf::from(location),
        reason: reason.to_string(),
    };
    if !path.exists() {
        return Err(unknown("no such file or directory"));
    }
    if path.is_dir() {
        if path.join("meta/info.json").is_file() {
            return Ok(InputKind::Dataset);
        }
        if path.join("metadata.yaml").is_file() {
            return Ok(InputKind::Rosbag2);
        }
        let inputs = scaledp_converter::collect_inputs(&[path.to_path_buf()])?;
        if inputs.is_empty() {
            return Err(unknown(
                "a directory with no recordings or bags (.mcap, .bag, .db3, rosbag2 directories) and no LeRobot dataset (meta/info.json)",
            ));
        }
        return Ok(InputKind::Directory);
    }
    if let Some(kind) = sniff(path) {
        return Ok(kind);
    }
    Err(unknown(
        "not an MCAP file, a ROS 1 bag, a rosbag2 .db3 file or directory, nor a LeRobot v3.0 dataset directory",
    ))
}

/// The inputs of a directory, sorted (`episode_NNNNNN.mcap` in episode order).
pub(crate) fn directory_inputs(path: &Path) -> Result<Vec<PathBuf>> {
    Ok(scaledp_converter::collect_inputs(&[path.to_path_buf()])?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds() {
        let dir = tempfile::tempdir().expect("tempdir");
        let d = dir.path();
        let write = |name: &str, bytes: &[u8]| {
            let p = d.join(name);
            std::fs::write(&p, bytes).expect("write");
            p.display().to_string()
        };
        assert_eq!(
            classify(&write("a.mcap", b"\x89MCAP0\r\nxx")).ok(),
            Some(InputKind::Mcap)
        );
        assert_eq!(
            classify(&write("b.bag", b"#ROSBAG V2.0\n")).ok(),
            Some(InputKind::Ros1Bag)
        );
        assert_eq!(
            classify(&write("c.db3", b"SQLite format 3\0")).ok(),
            Some(InputKind::Rosbag2)
        );
        let e = classify(&write("notes.txt", b"hello")).expect_err("not an input");
        assert!(e.to_string().contains("notes.txt: not an MCAP file"), "{e}");
        let e = classify(&d.join("missing").display().to_string()).expect_err("missing");
        assert!(e.to_string().ends_with("no such file or directory"), "{e}");
        assert_eq!(classify("s3://bucket/ds").ok(), Some(InputKind::Dataset));
        std::fs::create_dir_all(d.join("ds/meta")).expect("mkdir");
        std::fs::write(d.join("ds/meta/info.json"), "{}").expect("write");
        assert_eq!(
            classify(&d.join("ds").display().to_string()).ok(),
            Some(InputKind::Dataset)
        );
        std::fs::create_dir_all(d.join("empty")).expect("mkdir");
        let e = classify(&d.join("empty").display().to_string()).expect_err("empty dir");
        assert!(e.to_string().contains("no recordings or bags"), "{e}");
    }
}
