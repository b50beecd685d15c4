//! `scaledp bench record`, the recorder's soak, in short: 12 s of the reference load's topics at
//! 1 % of its image bytes (the rates are the reference's), three episodes of 4 s back to back, the recorder a child process. The episodes kept (`--keep`) are read here
//! message by message and must hold exactly what the report says was sent and recorded, per
//! topic; at this load on loopback nothing may be lost. A second, shorter run without `--keep`
//! must leave no episode file behind. The full soak (an hour at the whole load) is run by hand:
//! docs/benchmarks.md.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use scaledp_tests::scaledp_bin;

/// Minutes of load, seconds per episode, fraction of the reference's image bytes, seconds
/// between memory samples. (Three episodes of 10 s took 41 s of the suite: 4 s ones check the
/// same things.)
const MINUTES: &str = "0.2";
const EPISODE_S: &str = "4";
const LOAD: &str = "0.01";
const SAMPLE_S: &str = "1";

fn soak(out: &Path, minutes: &str, keep: bool) -> serde_json::Value {
    let mut cmd = Command::new(scaledp_bin());
    cmd.args(["bench", "record", "-q", "--minutes", minutes])
        .args(["--episode-seconds", EPISODE_S, "--load", LOAD])
        .args(["--sample-seconds", SAMPLE_S, "--min-free-gb", "1"])
        .arg("--out")
        .arg(out);
    if keep {
        cmd.arg("--keep");
    }
    let run = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("criteria: every episode run: yes; messages lost: 0 (none wanted);"),
        "{stdout}"
    );
    let report = std::fs::read(out.join("report.json")).unwrap();
    serde_json::from_slice(&report).unwrap()
}

/// Messages per topic in an MCAP file, read one by one.
fn count_messages(path: &Path) -> BTreeMap<String, u64> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *out.entry(m.unwrap().channel.topic.clone()).or_insert(0) += 1;
    }
    out
}

#[test]
fn a_short_soak_records_every_message_sent_and_reports_memory_and_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("soak");
    let r = soak(&out, MINUTES, true);
    let episodes = r["episodes"].as_array().unwrap();
    let planned = (MINUTES.parse::<f64>().unwrap() * 60.0 / EPISODE_S.parse::<f64>().unwrap())
        .ceil() as usize;
    assert_eq!(episodes.len(), planned, "{r}");
    let offered = r["offered"].as_object().unwrap();
    for (k, e) in episodes.iter().enumerate() {
        assert_eq!(e["check"], "ok", "episode {k}");
        assert_eq!(e["drained"], true, "episode {k}");
        let file = out
            .join("episodes")
            .join(format!("episode_{:06}.mcap", e["index"].as_u64().unwrap()));
        let in_file = count_messages(&file);
        let topics = e["topics"].as_object().unwrap();
        assert_eq!(
            topics.keys().collect::<Vec<_>>(),
            offered.keys().collect::<Vec<_>>(),
            "every topic of the load, in every episode"
        );
        for (topic, c) in topics {
            let sent = c["sent"].as_u64().unwrap();
            assert!(sent > 0, "episode {k}: nothing sent on {topic}");
            assert_eq!(c["recorded"], sent, "episode {k}: {topic}");
            assert_eq!(
                in_file.get(topic).copied(),
                Some(sent),
                "episode {k}: {topic} in the file"
            );
            assert_eq!(c["dropped"], 0, "episode {k}: {topic}");
        }
    }
    // Memory sampled every SAMPLE_S, the first episode's value kept apart, CPU measured.
    let samples = r["rss"].as_array().unwrap();
    let load_s: f64 = episodes.iter().map(|e| e["load_s"].as_f64().unwrap()).sum();
    assert!(
        samples.len() as f64 >= load_s / SAMPLE_S.parse::<f64>().unwrap(),
        "{} samples",
        samples.len()
    );
    assert!(samples.iter().all(|s| s[1].as_u64().unwrap() > 0));
    let base = r["rss_after_first"].as_u64().unwrap();
    let max = r["rss_max_after_first"].as_u64().unwrap();
    assert!(r["rss_peak"].as_u64().unwrap() >= max.max(base));
    let cpu = r["cpu_s"].as_f64().unwrap();
    let wall = r["wall_s"].as_f64().unwrap();
    let cores = r["cores"].as_f64().unwrap();
    assert!(cpu > 0.0 && cpu < wall * cores, "cpu {cpu} s over {wall} s");
    assert_eq!(r["worker_exit"], 0);

    // Without --keep, every episode is deleted once checked.
    let out = dir.path().join("soak2");
    let r = soak(&out, "0.05", false);
    let episodes = r["episodes"].as_array().unwrap();
    assert_eq!(episodes.len(), 1);
    assert_eq!(episodes[0]["deleted"], true);
    assert_eq!(episodes[0]["check"], "ok");
    let left: Vec<_> = std::fs::read_dir(out.join("episodes")).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}
