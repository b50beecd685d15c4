//! `scaledp convert` and `recover` on object storage when things go wrong (moto on loopback,
//! through the counting and breaking proxy, as in `convert_s3`): a killed job leaves nothing
//! visible and resumes; each storage failure is one line naming the URL, with nothing
//! half-written at the destination and the other inputs converted; a recording cut short in a
//! bucket is recovered there.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::Path;
use std::process::Output;
use std::sync::atomic::Ordering;

use scaledp_store::ObjectUrl;

use crate::convert_common::KEEP_UNLABELED;
use crate::convert_s3::{convert, episodes, text};
use scaledp_testkit::Proxy;
use scaledp_tests::s3::{shared, url};

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
