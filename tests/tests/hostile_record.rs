//! `scaledp record` when its disk fills up mid-episode, as a new user meets it: an unattended
//! run (`--episodes 2 --duration 8`) into a 1 MiB tmpfs (mounted in a private user and mount
//! namespace; where that is not allowed, a 1 MiB file size limit on the process instead). The
//! recorder must say so in one line with the OS's reason, end within a bounded time with exit
//! status 3, and leave the complete chunks of the episode readable (`scaledp recover`).

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use scaledp_tests::child::Reap;
use scaledp_tests::{free_endpoint, python, scaledp_bin, small_franka, write_rig_file};

/// Waits for `child` at most `limit`; None if it is still running then.
fn wait_bounded(mut child: std::process::Child, limit: Duration) -> Option<Output> {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if child.try_wait().unwrap().is_some() {
            return Some(child.wait_with_output().unwrap());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

/// Whether a tmpfs can be mounted in a private namespace here (unprivileged user namespaces).
fn tmpfs_allowed(dir: &Path) -> bool {
    Command::new("unshare")
        .args(["-rm", "sh", "-c", "mount -t tmpfs -o size=64k probe \"$0\""])
        .arg(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// How the disk fills: the command that runs `scaledp ARGS` on it, and the OS's words for it.
enum Full {
    /// A 1 MiB tmpfs on `dir` in a private namespace; its files are copied to `save` before the
    /// namespace (and with it the tmpfs) goes away.
    Tmpfs { dir: PathBuf, save: PathBuf },
    /// RLIMIT_FSIZE of 1 MiB (SIGXFSZ ignored, so writes fail with EFBIG).
    FileSizeLimit,
}

impl Full {
    fn reason(&self) -> &'static str {
        match self {
            Full::Tmpfs { .. } => "No space left on device",
            Full::FileSizeLimit => "File too large",
        }
    }

    fn command(&self, args: &[&std::ffi::OsStr]) -> Command {
        match self {
            Full::Tmpfs { dir, save } => {
                let mut c = Command::new("unshare");
                c.args(["-rm", "sh", "-c"])
                    .arg(
                        "dir=$1; save=$2; shift 2; \
                         mount -t tmpfs -o size=1m scaledp \"$dir\" || exit 97; \
                         \"$@\"; rc=$?; cp -p \"$dir\"/* \"$save\"/ 2>/dev/null; exit $rc",
                    )
                    .arg("sh")
                    .arg(dir)
                    .arg(save)
                    .arg(scaledp_bin())
                    .args(args);
                c
            }
            Full::FileSizeLimit => {
                let mut c = Command::new(python());
                c.args([
                    "-c",
                    "import os, resource, signal, sys\n\
                     signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n\
                     resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, 1 << 20))\n\
                     os.execv(sys.argv[1], sys.argv[1:])",
                ])
                .arg(scaledp_bin())
                .args(args);
                c
            }
        }
    }
}

#[test]
fn a_full_disk_ends_the_run_with_the_os_reason_and_exit_3() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = dir.path().join("demos");
    std::fs::create_dir_all(&out).unwrap();
    // SCALEDP_TEST_FSIZE_LIMIT=1 tries the fallback where a tmpfs could be mounted too.
    let fallback = std::env::var_os("SCALEDP_TEST_FSIZE_LIMIT").is_some();
    let full = if !fallback && tmpfs_allowed(&out) {
        let save = dir.path().join("saved");
        std::fs::create_dir_all(&save).unwrap();
        Full::Tmpfs {
            dir: out.clone(),
            save,
        }
    } else {
        Full::FileSizeLimit
    };
    let endpoint = free_endpoint();
    let _sim = Reap::new(
        Command::new(scaledp_bin())
            .args(["sim", "--duration", "120", "-q", "--listen", &endpoint])
            .arg("--rig")
            .arg(&rig_path)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let prefix = format!("test/full{}", std::process::id());
    let args: Vec<&std::ffi::OsStr> = vec![
        "record".as_ref(),
        "--rig".as_ref(),
        rig_path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--task".as_ref(),
        "t".as_ref(),
        "--episodes".as_ref(),
        "2".as_ref(),
        "--duration".as_ref(),
        "8".as_ref(),
        "--compression".as_ref(),
        "none".as_ref(),
        "--chunk-mib".as_ref(),
        "1".as_ref(),
        "--no-keyboard".as_ref(),
        // The disk guard would refuse to start on a 1 MiB disk: the full disk is the test.
        "--no-disk-guard".as_ref(),
        "--control-prefix".as_ref(),
        prefix.as_ref(),
        "--connect".as_ref(),
        endpoint.as_ref(),
    ];
    let t0 = Instant::now();
    let child = full
        .command(&args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Topics live within 10 s, the disk full in about 2 s of the first episode: well inside
    // the two episodes' 16 s, let alone a minute.
    let output = wait_bounded(child, Duration::from_secs(60))
        .expect("scaledp record did not end within 60 s on a full disk");
    let seconds = t0.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&output.stderr);
    eprintln!("{stderr}");
    assert_ne!(output.status.code(), Some(97), "mounting the tmpfs failed");
    assert_eq!(output.status.code(), Some(3), "data lost: {stderr}");
    assert!(seconds < 30.0, "ended {seconds:.1} s after it started");
    let failed: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("episode 0 failed: "))
        .collect();
    assert_eq!(failed.len(), 1, "{stderr}");
    assert!(
        failed[0].contains("episode_000000.mcap.partial") && failed[0].contains(full.reason()),
        "the OS's reason reaches the user: {}",
        failed[0]
    );

    // What was complete before the disk filled is readable: recover keeps it.
    let files = match &full {
        Full::Tmpfs { save, .. } => save.clone(),
        Full::FileSizeLimit => out.clone(),
    };
    let partial = files.join("episode_000000.mcap.partial");
    assert!(
        partial.exists(),
        "{:?}",
        std::fs::read_dir(&files).unwrap().collect::<Vec<_>>()
    );
    let fixed = dir.path().join("recovered.mcap");
    let rec = Command::new(scaledp_bin())
        .args(["recover", "-q"])
        .arg(&partial)
        .arg("--output")
        .arg(&fixed)
        .output()
        .unwrap();
    // 3: the end of the file (the chunk the disk had no room for) was lost, as expected.
    assert!(
        matches!(rec.status.code(), Some(0 | 3)),
        "{}",
        String::from_utf8_lossy(&rec.stderr)
    );
    let bytes = std::fs::read(&fixed).unwrap();
    let mut n = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        m.unwrap();
        n += 1;
    }
    assert!(n > 0, "no message survived");
}
