//! Labels, operators and verdicts through `scaledp convert`: unlabelled episodes (a plain stop,
//! and a recording without any episode metadata) are converted only when asked — no
//! `--unlabeled`: nothing converted, one line naming each; `skip`: left out; `keep`: stored as
//! `unlabeled`, never as a success — and every episode's operator, label and verdict (the
//! recorder's `scaledp.verdict` record when the file has one, else convert's own) land in
//! `meta/episodes/`.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use scaledp_schema::episode::END_RECORD;
use scaledp_schema::{EpisodeMetadata, Label};
use scaledp_tests::{convert_cli, episode_column, small_franka, synth_episode, write_rig_file};

/// The recorder's verdict record (what `scaledp record` stores when an episode ends).
const VERDICT_RECORD: &str = "scaledp.verdict";

/// `src` rewritten to `dst` with its episode record's label and operator replaced (None: no
/// episode record at all) and, when given, a `scaledp.verdict` record (accepted, reason, line).
fn relabel(
    src: &Path,
    dst: &Path,
    label: Option<(Label, &str)>,
    verdict: Option<(bool, &str, &str)>,
) {
    let bytes = std::fs::read(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    for idx in &summary.metadata_indexes {
        let mut m = mcap::read::metadata(&bytes, idx).unwrap();
        if m.name != END_RECORD {
            continue; // the start record says the same; the end record is rewritten
        }
        let Some((label, operator)) = label else {
            continue;
        };
        let mut meta =
            EpisodeMetadata::from_records(&BTreeMap::from([(m.name.clone(), m.metadata.clone())]))
                .unwrap()
                .unwrap();
        meta.label = Some(label);
        meta.operator = operator.into();
        m.metadata = meta.end_record();
        w.write_metadata(&m).unwrap();
    }
    if let Some((accepted, reason, line)) = verdict {
        w.write_metadata(&mcap::records::Metadata {
            name: VERDICT_RECORD.into(),
            metadata: BTreeMap::from([
                ("accepted".into(), accepted.to_string()),
                ("reason".into(), reason.into()),
                ("line".into(), line.into()),
            ]),
        })
        .unwrap();
    }
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        w.write(&m.unwrap()).unwrap();
    }
    w.finish().unwrap();
}

/// A string or boolean column of `meta/episodes` as text (None for a null).
fn strings(ds: &Path, column: &str) -> Vec<Option<String>> {
    episode_column(ds, column)
        .into_iter()
        .map(|v| match v {
            serde_json::Value::Null => None,
            serde_json::Value::String(s) => Some(s),
            other => Some(other.to_string()),
        })
        .collect()
}

fn run(inputs: &[PathBuf], ds: &Path, rig: &Path, extra: &[&str]) -> std::process::Output {
    let mut args: Vec<&OsStr> = inputs.iter().map(|p| p.as_os_str()).collect();
    args.extend([
        OsStr::new("--out"),
        ds.as_os_str(),
        OsStr::new("--rig"),
        rig.as_os_str(),
    ]);
    // The recording without metadata stores no task either.
    args.extend(
        [
            "--size",
            "32x24",
            "--jobs",
            "1",
            "--task",
            "stack the cubes",
        ]
        .map(OsStr::new),
    );
    args.extend(extra.iter().map(OsStr::new));
    convert_cli(&args)
}

#[test]
fn unlabelled_episodes_are_a_choice_and_every_episode_says_who_what_and_how_it_was_judged() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let rig_path = write_rig_file(dir.path(), &rig);
    let raw = dir.path().join("raw.mcap");
    synth_episode(&raw, &rig, 3, 3.0);
    let rec = dir.path().join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    let name = |k: usize| rec.join(format!("episode_{k:06}.mcap"));
    let recorder_line = "accepted: 2.9 of 3.0 s kept, as the recorder saw it";
    relabel(
        &raw,
        &name(0),
        Some((Label::Success, "ana")),
        Some((true, "", recorder_line)),
    );
    relabel(&raw, &name(1), Some((Label::Unlabeled, "ben")), None);
    relabel(&raw, &name(2), Some((Label::Failure, "ana")), None);
    relabel(&raw, &name(3), None, None);
    let inputs: Vec<PathBuf> = (0..4).map(name).collect();

    // No choice made: nothing converted, one line naming both unlabelled episodes.
    let ds = dir.path().join("refused");
    let out = run(&inputs, &ds, &rig_path, &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("unlabelled"))
        .collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    for k in [1, 3] {
        assert!(
            lines[0].contains(&name(k).display().to_string()),
            "{}",
            lines[0]
        );
    }
    for k in [0, 2] {
        assert!(
            !lines[0].contains(&name(k).display().to_string()),
            "{}",
            lines[0]
        );
    }
    assert!(lines[0].contains("2 unlabelled episodes") && lines[0].contains("--unlabeled keep"));
    assert!(!ds.join("meta/info.json").exists());

    // skip: the success alone (the failure is skipped as before).
    let ds = dir.path().join("skipped");
    let out = run(&inputs, &ds, &rig_path, &["--unlabeled", "skip"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stdout.contains("1 converted"),
        "{stdout}{stderr}"
    );
    assert_eq!(
        stderr.matches("unlabelled (--unlabeled skip)").count(),
        2,
        "{stderr}"
    );
    assert_eq!(strings(&ds, "scaledp/label"), vec![Some("success".into())]);

    // keep (with the failure): four episodes, labels as recorded, the unlabelled ones
    // 'unlabeled'; the recorder's verdict where it gave one, convert's own elsewhere.
    let ds = dir.path().join("kept");
    let out = run(
        &inputs,
        &ds,
        &rig_path,
        &["--unlabeled", "keep", "--include-failures"],
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.contains("4 converted"),
        "{stdout}"
    );
    let some = |v: &[&str]| v.iter().map(|s| Some(s.to_string())).collect::<Vec<_>>();
    assert_eq!(
        strings(&ds, "scaledp/label"),
        some(&["success", "unlabeled", "failure", "unlabeled"])
    );
    assert_eq!(
        strings(&ds, "scaledp/operator"),
        some(&["ana", "ben", "ana", ""])
    );
    assert_eq!(
        strings(&ds, "scaledp/verdict_by"),
        some(&["record", "convert", "convert", "convert"])
    );
    assert_eq!(
        strings(&ds, "scaledp/verdict_accepted"),
        some(&["true", "true", "true", "true"])
    );
    let verdicts = strings(&ds, "scaledp/verdict");
    assert_eq!(verdicts[0].as_deref(), Some(recorder_line));
    for v in &verdicts[1..] {
        let v = v.as_deref().unwrap();
        assert!(v.starts_with("accepted: ") && v.contains(" ticks, "), "{v}");
    }
    // Convert's own verdict quotes the episode's alignment report.
    let sidecar = scaledp_tests::read_json(&ds.join("meta/scaledp.json"));
    let report = &sidecar["episodes"][1]["report"];
    let want = format!(
        ", {} ticks, {} invalid, {} trimmed, ",
        report["ticks"], report["invalid"], report["trimmed"]
    );
    assert!(
        verdicts[1].as_deref().unwrap().contains(&want),
        "{verdicts:?} {want}"
    );
    // Nowhere is an unlabelled episode a success: the sidecar says the same.
    let labels: Vec<&str> = sidecar["episodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["recorded"]["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["success", "unlabeled", "failure", "unlabeled"]);
    scaledp_tests::check_dataset(&ds);
}
