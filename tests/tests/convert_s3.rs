//! `scaledp convert`, `dataset merge` and `recover` on object storage, against a real S3
//! endpoint (moto from the tests' venv, on loopback, with IAM auth; one server for this test
//! binary), through a proxy that counts, records and breaks the traffic: recordings and bags
//! converted from a bucket equal the local conversion; a re-run skips every input without
//! reading it; an episode recorded as failed is skipped from its metadata record alone; a
//! killed job leaves nothing visible and resumes; each storage failure is one line naming the
//! URL, with nothing half-written at the destination and the other inputs converted.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::Path;
use std::process::Output;
use std::sync::atomic::Ordering;

use scaledp_store::ObjectUrl;

use crate::convert_common::KEEP_UNLABELED;
use scaledp_testkit::Proxy;
use scaledp_tests::s3::{files, shared, url};
use scaledp_tests::{make_bags, small_franka, synth_episode, write_rig_file};

/// stdout and stderr of a run, for messages.
fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `n` recorder episodes of 2 s (seeds 1..=n) under `dir`.
fn episodes(dir: &Path, n: u64) {
    std::fs::create_dir_all(dir).unwrap();
    for seed in 1..=n {
        let path = dir.join(format!("episode_{seed:06}.mcap"));
        synth_episode(&path, &small_franka(), seed, 2.0);
    }
}

/// Runs `scaledp convert INPUT --out OUT ARGS` against `endpoint`.
fn convert(endpoint: &str, input: &str, out: &str, args: &[&str]) -> Output {
    let jobs: &[&str] = if args.contains(&"--jobs") {
        &[]
    } else {
        &["--jobs", "2"]
    };
    shared()
        .scaledp(endpoint)
        .args(["convert", input, "--out", out])
        .args(KEEP_UNLABELED)
        .args(jobs)
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_bucket_converts_like_a_directory_and_a_rerun_reads_nothing_again() {
    let s3 = shared();
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    episodes(&rec, 2);
    make_bags(&rec.join("bags"));
    // Skipped in a bucket as in a directory.
    std::fs::copy(
        rec.join("episode_000001.mcap"),
        rec.join("episode_000009.mcap.partial"),
    )
    .unwrap();
    episodes(&rec.join("discarded"), 1);
    let rig = write_rig_file(dir.path(), &small_franka());
    let args = ["--rig", rig.to_str().unwrap(), "--task", "pick up the cube"];
    s3.upload_dir(&rec, &url("data", "roundtrip/rec"));

    let local = dir.path().join("local");
    let out = convert(
        &s3.endpoint,
        rec.to_str().unwrap(),
        local.to_str().unwrap(),
        &args,
    );
    assert!(out.status.success(), "{}", text(&out));
    let proxy = Proxy::start(&s3.endpoint);
    let remote = url("data", "roundtrip/ds");
    let out = convert(
        &proxy.endpoint,
        "s3://data/roundtrip/rec/",
        &remote.to_string(),
        &args,
    );
    let report = text(&out);
    assert!(out.status.success(), "{report}");
    let local_report = String::from_utf8_lossy(&out.stdout);
    assert!(
        local_report.contains("converted") && !report.contains("failed:"),
        "{report}"
    );

    // The same data files byte for byte; the same content hashes (local files and their
    // objects hash alike); sources named by URL; nothing else left under the prefix.
    let want = files(&local);
    let got = s3.objects(&remote);
    let keys =
        |m: &std::collections::BTreeMap<String, Vec<u8>>| m.keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(&got), keys(&want));
    for (k, v) in &want {
        if k.starts_with("data/") {
            assert!(got[k] == *v, "{k} differs");
        }
    }
    let record = |bytes: &[u8]| serde_json::from_slice::<serde_json::Value>(bytes).unwrap();
    let (l, r) = (
        record(&want["meta/scaledp.json"]),
        record(&got["meta/scaledp.json"]),
    );
    let episodes_of = |v: &serde_json::Value| v["episodes"].as_array().unwrap().clone();
    assert_eq!(episodes_of(&l).len(), 7, "2 recordings + 5 bags");
    for (a, b) in episodes_of(&l).iter().zip(episodes_of(&r)) {
        assert_eq!(a["source_hash"], b["source_hash"]);
        let name = Path::new(a["source"].as_str().unwrap())
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let source = b["source"].as_str().unwrap();
        assert!(
            source.starts_with("s3://data/roundtrip/rec/")
                && source.contains(name.split('#').next().unwrap()),
            "{source}"
        );
        assert!(b["source_etag"].is_string() && a.get("source_etag").is_none());
    }

    // A re-run skips every input by the version it was read at: the listing, the record and
    // the job marker are all it reads.
    let before = proxy.state.bytes_down.load(Ordering::SeqCst);
    let requests_before = proxy.requests().len();
    let again = convert(
        &proxy.endpoint,
        "s3://data/roundtrip/rec/",
        &remote.to_string(),
        &args,
    );
    let report = text(&again);
    assert!(
        again.status.success() && report.contains("0 converted") && report.contains("7 skipped"),
        "{report}"
    );
    let read = proxy.state.bytes_down.load(Ordering::SeqCst) - before;
    let recordings: u64 = files(&rec).values().map(|v| v.len() as u64).sum();
    assert!(
        read * 10 < recordings,
        "the re-run read {read} bytes of {recordings}"
    );
    assert!(
        !proxy.requests()[requests_before..]
            .iter()
            .any(|r| r.starts_with("GET /data/roundtrip/rec/")),
        "an input was read again: {:?}",
        &proxy.requests()[requests_before..]
    );
    assert_eq!(s3.objects(&remote), got, "the re-run changed the dataset");
}

/// A copy of the MCAP `src` whose end-of-episode record says `outcome` (if given), in chunks
/// of `chunk_bytes`.
fn rewrite(src: &Path, dst: &Path, outcome: Option<&str>, chunk_bytes: u64) {
    let bytes = std::fs::read(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .chunk_size(Some(chunk_bytes))
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    for r in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Metadata(mut m) = r.unwrap() {
            if let Some(o) = outcome.filter(|_| m.name == scaledp_schema::episode::END_RECORD) {
                m.metadata.insert("outcome".into(), o.into());
            }
            w.write_metadata(&m).unwrap();
        }
    }
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        w.write(&m.unwrap()).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_failed_episode_is_skipped_from_its_metadata_and_frames_come_from_the_chunk_index() {
    let s3 = shared();
    let dir = tempfile::tempdir().unwrap();
    episodes(dir.path(), 1);
    let rec = dir.path().join("rec");
    std::fs::create_dir(&rec).unwrap();
    // Chunks of 16 KiB: about one 64×48 frame each, as rosbag2's 768 KiB chunks hold one HD
    // frame.
    let original = dir.path().join("episode_000001.mcap");
    rewrite(&original, &rec.join("episode_000001.mcap"), None, 16 << 10);
    rewrite(
        &original,
        &rec.join("episode_000002.mcap"),
        Some("failure"),
        16 << 10,
    );
    s3.upload_dir(&rec, &url("data", "ranged/rec"));
    let size = |name: &str| std::fs::metadata(rec.join(name)).unwrap().len();

    let proxy = Proxy::start(&s3.endpoint);
    let failed = "s3://data/ranged/rec/episode_000002.mcap";
    let out = convert(&proxy.endpoint, failed, "s3://data/ranged/ds-failed", &[]);
    let report = text(&out);
    assert!(
        report.contains("skipped") && report.contains("recorded outcome: failure"),
        "{report}"
    );
    let read = proxy.state.bytes_down.load(Ordering::SeqCst);
    assert!(
        read * 2 < size("episode_000002.mcap"),
        "read {read} bytes to skip it"
    );

    // Split on time gaps, no frame is encoded on the first read: all come from the second,
    // which fetches only the chunks holding them (a 30 Hz camera at 10 Hz: a third).
    let proxy = Proxy::start(&s3.endpoint);
    let good = "s3://data/ranged/rec/episode_000001.mcap";
    let out = convert(
        &proxy.endpoint,
        good,
        "s3://data/ranged/ds",
        &["--split-gap", "1000"],
    );
    assert!(
        out.status.success() && text(&out).contains("1 converted"),
        "{}",
        text(&out)
    );
    let ranged = proxy
        .requests()
        .iter()
        .filter(|r| r.starts_with("GET /data/ranged/rec/episode_000001.mcap"))
        .count();
    let read = proxy.state.bytes_down.load(Ordering::SeqCst);
    assert!(ranged > 2, "{ranged} GETs of the recording");
    // The first read is the whole object; the second well under another.
    let second = read.saturating_sub(size("episode_000001.mcap") + (64 << 10));
    assert!(
        second * 10 < size("episode_000001.mcap") * 7,
        "read {read} bytes"
    );
}

/// The `error:` lines of a failed run's stderr.
fn error_lines(o: &Output) -> Vec<String> {
    String::from_utf8_lossy(&o.stderr)
        .lines()
        .filter(|l| l.starts_with("error:"))
        .map(str::to_string)
        .collect()
}

/// Asserts `o` failed (exit 1) with exactly one error line containing every part of `want`.
fn one_clear_line(o: &Output, want: &[&str]) {
    let lines = error_lines(o);
    assert_eq!(o.status.code(), Some(1), "{}", text(o));
    assert_eq!(lines.len(), 1, "{}", text(o));
    for w in want {
        assert!(lines[0].contains(w), "{:?} lacks {w:?}", lines[0]);
    }
}

/// The keys under `prefix` that a reader of the dataset would see (anything but the staging).
fn visible(prefix: &ObjectUrl) -> Vec<String> {
    shared()
        .objects(prefix)
        .into_keys()
        .filter(|k| !k.starts_with(".scaledp-staging/"))
        .collect()
}

#[test]
fn a_killed_job_leaves_nothing_visible_and_its_rerun_equals_one_run() {
    let s3 = shared();
    let dir = tempfile::tempdir().unwrap();
    episodes(&dir.path().join("rec"), 4);
    s3.upload_dir(&dir.path().join("rec"), &url("data", "killed/rec"));
    // Every episode in a data file of its own, so each is staged as soon as it is committed.
    let args = ["--file-size-mib", "0", "--jobs", "1"];
    let reference = url("data", "killed/reference");
    let out = convert(
        &s3.endpoint,
        "s3://data/killed/rec/",
        &reference.to_string(),
        &args,
    );
    assert!(out.status.success(), "{}", text(&out));

    // Reading the third recording stalls; the job is killed once two episodes are staged.
    let proxy = Proxy::start(&s3.endpoint);
    proxy.set_hook(Some(std::sync::Arc::new(|line: &str| {
        if line.contains("episode_000003.mcap") {
            std::thread::sleep(std::time::Duration::from_secs(20));
        }
    })));
    let ds = url("data", "killed/ds");
    let mut job = s3
        .scaledp(&proxy.endpoint)
        .args(["convert", "s3://data/killed/rec/", "--out", &ds.to_string()])
        .args(KEEP_UNLABELED)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let checkpoint = ds.join(".scaledp-staging/checkpoint.json");
    let bucket = s3.bucket("data");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let staged = bucket.get(&checkpoint).unwrap().map_or(0, |b| {
            let v: serde_json::Value = serde_json::from_slice(&b).unwrap();
            v["sidecar"]["episodes"].as_array().unwrap().len()
        });
        if staged == 2 {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no checkpoint of 2 episodes"
        );
        assert!(
            job.try_wait().unwrap().is_none(),
            "the job ended before it was killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    job.kill().unwrap();
    job.wait().unwrap();
    proxy.set_hook(None);
    assert_eq!(
        visible(&ds),
        Vec::<String>::new(),
        "a killed job left a partial dataset"
    );

    let out = convert(
        &s3.endpoint,
        "s3://data/killed/rec/",
        &ds.to_string(),
        &args,
    );
    let report = text(&out);
    assert!(
        report.contains("2 converted") && report.contains("2 skipped"),
        "{report}"
    );
    assert_eq!(s3.objects(&ds), s3.objects(&reference));
}

#[test]
fn storage_failures_are_one_clear_line_and_leave_nothing_half_written() {
    let s3 = shared();
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    episodes(&rec, 3);
    s3.upload_dir(&rec, &url("data", "failures/rec"));
    let local = dir.path().join("out");
    let local = local.to_str().unwrap();

    let out = convert(&s3.endpoint, "s3://no-such-bucket/rec/", local, &[]);
    one_clear_line(
        &out,
        &[
            "s3://no-such-bucket/rec/",
            "no such bucket 'no-such-bucket'",
        ],
    );
    let out = convert(
        &s3.endpoint,
        rec.to_str().unwrap(),
        "s3://no-such-bucket/ds",
        &[],
    );
    one_clear_line(&out, &["s3://no-such-bucket/ds/", "no such bucket"]);
    let out = s3
        .scaledp(&s3.endpoint)
        .env("AWS_SECRET_ACCESS_KEY", "not-the-secret")
        .args(["convert", "s3://data/failures/rec/", "--out", local])
        .args(KEEP_UNLABELED)
        .output()
        .unwrap();
    one_clear_line(
        &out,
        &[
            "s3://data/failures/rec/",
            "credentials were refused (SignatureDoesNotMatch)",
        ],
    );
    let out = convert(
        &s3.endpoint,
        "s3://data/failures/rec/",
        "s3://locked/ds",
        &[],
    );
    one_clear_line(
        &out,
        &[
            "s3://locked/ds/.scaledp-staging/job.json",
            "access denied to write (AccessDenied)",
        ],
    );
    assert!(s3.objects(&url("locked", "")).is_empty());
    assert!(!Path::new(local).exists(), "a failed job wrote {local}");

    // An object removed after the listing: that input fails, the others are converted.
    let proxy = Proxy::start(&s3.endpoint);
    let bucket = s3.bucket("data");
    let doomed = url("data", "failures/rec/episode_000003.mcap");
    proxy.set_hook(Some(std::sync::Arc::new(move |line: &str| {
        if line.contains("episode_000001.mcap") {
            bucket.delete(std::slice::from_ref(&doomed)).unwrap();
        }
    })));
    let ds = url("data", "failures/ds");
    let out = convert(
        &proxy.endpoint,
        "s3://data/failures/rec/",
        &ds.to_string(),
        &["--jobs", "1"],
    );
    let report = text(&out);
    assert_eq!(out.status.code(), Some(3), "{report}");
    assert!(
        report.contains("2 converted") && report.contains("1 failed"),
        "{report}"
    );
    let failed: Vec<&str> = report
        .lines()
        .filter(|l| l.starts_with("failed:"))
        .collect();
    assert_eq!(
        failed,
        ["failed: s3://data/failures/rec/episode_000003.mcap: no such object"]
    );
    proxy.set_hook(None);
    let reference = url("data", "failures/reference");
    let out = convert(
        &s3.endpoint,
        "s3://data/failures/rec/",
        &reference.to_string(),
        &[],
    );
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(s3.objects(&ds), s3.objects(&reference));

    // The endpoint cut in the middle of the first data upload: retried, the job completes
    // as if nothing happened; cut for good: one line, nothing visible, and a re-run completes.
    for (cuts, prefix) in [(1, "failures/cut-once"), (usize::MAX, "failures/cut")] {
        let proxy = Proxy::start(&s3.endpoint);
        let state = proxy.state.clone();
        let armed = std::sync::atomic::AtomicBool::new(true);
        proxy.set_hook(Some(std::sync::Arc::new(move |line: &str| {
            let upload = line.starts_with("PUT") && line.contains(".scaledp-staging/data/");
            if upload && armed.swap(false, Ordering::SeqCst) {
                state.cut_uploads.store(cuts, Ordering::SeqCst);
            }
        })));
        let ds = url("data", prefix);
        let out = convert(
            &proxy.endpoint,
            "s3://data/failures/rec/",
            &ds.to_string(),
            &[],
        );
        if cuts == 1 {
            assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        } else {
            one_clear_line(
                &out,
                &[
                    &format!("s3://data/{prefix}/.scaledp-staging/data/chunk-000/file-000.parquet"),
                    "network error",
                    "gave up after the retries",
                ],
            );
            assert_eq!(visible(&ds), Vec::<String>::new());
            let out = convert(
                &s3.endpoint,
                "s3://data/failures/rec/",
                &ds.to_string(),
                &[],
            );
            assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        }
        assert_eq!(s3.objects(&ds), s3.objects(&reference), "{prefix}");
    }
}

#[test]
fn a_cut_recording_in_a_bucket_is_recovered_there() {
    let s3 = shared();
    let dir = tempfile::tempdir().unwrap();
    episodes(dir.path(), 1);
    let whole = std::fs::read(dir.path().join("episode_000001.mcap")).unwrap();
    let rec = dir.path().join("rec");
    std::fs::create_dir(&rec).unwrap();
    let partial = rec.join("episode_000001.mcap.partial");
    std::fs::write(&partial, &whole[..whole.len() * 3 / 4]).unwrap();
    s3.upload_dir(&rec, &url("data", "recover"));
    let recover = || {
        s3.scaledp(&s3.endpoint)
            .args(["recover", "s3://data/recover/episode_000001.mcap.partial"])
            .output()
            .unwrap()
    };
    let out = recover();
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    assert!(
        text(&out).starts_with("s3://data/recover/episode_000001.mcap: "),
        "{}",
        text(&out)
    );
    let out = convert(
        &s3.endpoint,
        "s3://data/recover/",
        "s3://data/recover-ds",
        &[],
    );
    assert!(text(&out).contains("1 converted"), "{}", text(&out));
    let out = recover();
    one_clear_line(
        &out,
        &["s3://data/recover/episode_000001.mcap: output exists"],
    );
}
