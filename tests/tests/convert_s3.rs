//! `scaledp convert`, `dataset merge` and `recover` on object storage, against a real S3
//! endpoint (moto from the tests' venv, on loopback, with IAM auth; one server for this test
//! binary), through a proxy that counts, records and breaks the traffic: recordings and bags
//! converted from a bucket equal the local conversion; a re-run skips every input without
//! reading it; an episode recorded as failed is skipped from its metadata record alone. (A
//! killed job, storage failures and recover: `convert_s3_faults`.)

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::Path;
use std::process::Output;
use std::sync::atomic::Ordering;

use crate::convert_common::KEEP_UNLABELED;
use scaledp_testkit::Proxy;
use scaledp_tests::s3::{files, shared, url};
use scaledp_tests::{make_bags, small_franka, synth_episode, write_rig_file};

/// stdout and stderr of a run, for messages.
pub(crate) fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `n` recorder episodes of 2 s (seeds 1..=n) under `dir`.
pub(crate) fn episodes(dir: &Path, n: u64) {
    std::fs::create_dir_all(dir).unwrap();
    for seed in 1..=n {
        let path = dir.join(format!("episode_{seed:06}.mcap"));
        synth_episode(&path, &small_franka(), seed, 2.0);
    }
}

/// Runs `scaledp convert INPUT --out OUT ARGS` against `endpoint`.
pub(crate) fn convert(endpoint: &str, input: &str, out: &str, args: &[&str]) -> Output {
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
