//! `scaledp convert` over the hostile-input corpus (`tests/py/make_corpus.py`): every kind of
//! input broken every way, mixed with the same recording in every good format, in one run with
//! no `--rig` (as a new user runs it). Every good input converts; every bad one gets exactly one
//! line naming it and its reason, in words about the input (never an internal library message);
//! nothing panics; memory stays bounded; the exit status is 3.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use scaledp_tests::{check_dataset, run_python, scaledp_bin};

/// Peak resident memory allowed to the whole conversion (it holds one small input per job).
const MAX_PEAK_RSS: u64 = 768 << 20;

/// Phrases of libraries' own messages that must never reach a user as the reason an input failed.
const INTERNAL: [&str; 6] = [
    "Invalid argument error",
    "record batch",
    "panicked",
    "internal error",
    "RUST_BACKTRACE",
    "unwrap",
];

/// `VmHWM` of a running process (bytes).
fn vm_hwm(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
}

struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    seconds: f64,
    peak_rss: u64,
}

/// Runs `scaledp convert ARGS -q`, sampling its peak memory until it exits.
fn convert_measured(args: &[&std::ffi::OsStr]) -> Run {
    let t0 = Instant::now();
    let mut child = Command::new(scaledp_bin())
        .arg("convert")
        .args(args)
        .args(["--unlabeled", "keep", "-q"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let out = child.stdout.take().unwrap();
    let err = child.stderr.take().unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            r.read_to_string(&mut s).unwrap();
            s
        })
    };
    let (out, err) = (read(Box::new(out)), read(Box::new(err)));
    let mut peak = 0;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        peak = peak.max(vm_hwm(pid).unwrap_or(0));
        assert!(t0.elapsed() < Duration::from_secs(120), "convert hangs");
        std::thread::sleep(Duration::from_millis(5));
    };
    Run {
        code: status.code(),
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
        seconds: t0.elapsed().as_secs_f64(),
        peak_rss: peak,
    }
}

/// `scaledp/reordered_messages` of every episode, by source path.
fn reordered_by_source(ds: &Path) -> BTreeMap<String, u64> {
    let sources = scaledp_tests::episode_column(ds, "scaledp/source");
    let counts = scaledp_tests::episode_column(ds, "scaledp/reordered_messages");
    sources
        .iter()
        .zip(&counts)
        .map(|(s, n)| (s.as_str().unwrap().to_string(), n.as_u64().unwrap()))
        .collect()
}

#[test]
fn the_corpus_converts_its_good_inputs_and_names_every_bad_one_once() {
    let dir = tempfile::tempdir().unwrap();
    let corpus = dir.path().join("corpus");
    let manifest = run_python("make_corpus.py", &[&corpus]);
    let good: Vec<&str> = manifest["good"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    let bad: BTreeMap<&str, &str> = manifest["bad"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str().unwrap()))
        .collect();
    assert!(
        good.len() + bad.len() >= 30,
        "the corpus has 30 cases or more"
    );

    let ds = dir.path().join("ds");
    let run = convert_measured(&[
        corpus.as_os_str(),
        "--task".as_ref(),
        "stack the cubes".as_ref(),
        "--out".as_ref(),
        ds.as_os_str(),
    ]);
    eprintln!(
        "corpus of {} inputs: {:.1} s, peak RSS {:.0} MiB",
        good.len() + bad.len(),
        run.seconds,
        run.peak_rss as f64 / f64::from(1 << 20)
    );
    let all = format!("{}\n{}", run.stdout, run.stderr);
    assert_eq!(run.code, Some(3), "finished but lost data:\n{all}");
    assert!(
        run.stdout.contains(&format!("{} converted", good.len()))
            && run.stdout.contains(&format!("{} failed", bad.len())),
        "{all}"
    );
    for phrase in INTERNAL {
        assert!(!all.contains(phrase), "'{phrase}' reached the user:\n{all}");
    }
    assert!(
        run.peak_rss > 0 && run.peak_rss < MAX_PEAK_RSS,
        "peak RSS {} MiB",
        run.peak_rss >> 20
    );

    // One line per bad input on stdout, naming it (or a file inside it) and the reason.
    let failed: Vec<&str> = run
        .stdout
        .lines()
        .filter(|l| l.starts_with("failed: "))
        .collect();
    assert_eq!(failed.len(), bad.len(), "{}", run.stdout);
    let mut wrong = Vec::new();
    for (name, reason) in &bad {
        let path = corpus.join(name).display().to_string();
        let names = |l: &&&str| {
            l.match_indices(&path)
                .any(|(i, _)| matches!(l.as_bytes().get(i + path.len()), Some(b':' | b'/' | b' ')))
        };
        let lines: Vec<&&str> = failed.iter().filter(names).collect();
        if lines.len() != 1 || !lines[0].contains(reason) {
            wrong.push(format!(
                "{name}: want one line with '{reason}', got {lines:?}"
            ));
        }
        // The progress view repeats a failure on stderr at most once.
        let on_stderr = run.stderr.lines().filter(|l| l.contains(&path)).count();
        assert!(on_stderr <= 1, "{name}: {on_stderr} lines on stderr");
    }
    assert!(wrong.is_empty(), "{}\n\n{}", wrong.join("\n"), run.stdout);

    // Every good input is in the dataset, which LeRobot's reader accepts.
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], good.len());
    let reordered = reordered_by_source(&ds);
    let wobble = corpus.join("good_wobbling_stamps.mcap");
    assert!(
        reordered[&wobble.display().to_string()] > 0,
        "reordered stamps are counted: {reordered:?}"
    );
    let steady = corpus.join("good_standalone.mcap");
    assert_eq!(reordered[&steady.display().to_string()], 0);
}
