//! `scaledp record --episode-time --reset-time` as a process beside the simulated rig, steered
//! only by words on its control key, in both phases: a discard while the first episode records
//! (it does not count toward --episodes and the next starts after the reset), a label and the
//! next of two --task values in a reset, and the last episode kept unlabelled when its reset is
//! over. Each episode's verdict comes on the status key when it ends and is in its file.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use scaledp_recorder::net;
use scaledp_sim::SimOptions;
use scaledp_tests::child::{wait_status, Reap};
use scaledp_tests::{episode_metadata, free_endpoint, scaledp_bin, small_franka, write_rig_file};
use zenoh::Wait;

/// How long a status event may take.
const WAIT: Duration = Duration::from_secs(30);

#[test]
fn a_timed_session_takes_words_in_both_phases_and_counts_kept_episodes() {
    // Light streams (15 fps, a 100 Hz arm) so a debug build keeps them at their rates: the
    // session waits for live topics before each start.
    let mut rig = small_franka();
    for c in &mut rig.cameras {
        c.fps = 15.0;
    }
    rig.arms[0].rate_hz = 100.0;
    let dir = tempfile::tempdir().unwrap();
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = dir.path().join("rec");
    let endpoint = free_endpoint();
    let session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let sim = SimOptions::new(rig.clone())
        .seed(5)
        .spawn(&session)
        .unwrap();
    let prefix = format!("test/timed{}", std::process::id());
    let (tx, statuses) = mpsc::channel::<serde_json::Value>();
    let _sub = session
        .declare_subscriber(format!("{prefix}/status"))
        .callback(move |s| {
            let _ = tx.send(serde_json::from_slice(&s.payload().to_bytes()).unwrap());
        })
        .wait()
        .unwrap();
    let child = Reap(Some(
        Command::new(scaledp_bin())
            .args(["record", "--task", "first task", "--task", "second task"])
            .args([
                "--episodes",
                "2",
                "--episode-time",
                "1",
                "--reset-time",
                "0.5",
            ])
            .args(["--no-keyboard", "-q", "--control-prefix", &prefix])
            .args(["--connect", &endpoint])
            .arg("--rig")
            .arg(&rig_path)
            .arg("--out")
            .arg(&out)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let control = |word: &str| {
        session
            .put(format!("{prefix}/control"), word)
            .wait()
            .unwrap();
    };
    // Episode 0 starts by itself once the topics are live; discarded while it records.
    assert_eq!(wait_status(&statuses, "started", WAIT)["episode"], 0);
    std::thread::sleep(Duration::from_millis(300));
    control("discard");
    let discarded = wait_status(&statuses, "finished", WAIT);
    assert_eq!(
        (&discarded["episode"], &discarded["outcome"]),
        (&0.into(), &"discarded".into())
    );
    // Episode 1 after the reset; it ends on its timer, held, and is labelled in its reset.
    let t = Instant::now();
    assert_eq!(wait_status(&statuses, "started", WAIT)["episode"], 1);
    assert!(
        t.elapsed() >= Duration::from_millis(400),
        "{:?}",
        t.elapsed()
    );
    let ended = wait_status(&statuses, "ended", WAIT);
    assert_eq!(ended["episode"], 1);
    let verdict = ended["verdict"].clone();
    assert!(verdict["accepted"].is_boolean(), "{ended}");
    control("success");
    control("next-task");
    let one = wait_status(&statuses, "finished", WAIT);
    assert_eq!(
        (&one["episode"], &one["outcome"]),
        (&1.into(), &"success".into())
    );
    assert_eq!(one["verdict"], verdict);
    assert_eq!(wait_status(&statuses, "task", WAIT)["task"], "second task");
    // Episode 2, the last: kept unlabelled when its reset is over, then the session ends.
    assert_eq!(wait_status(&statuses, "started", WAIT)["episode"], 2);
    assert_eq!(wait_status(&statuses, "ended", WAIT)["episode"], 2);
    let two = wait_status(&statuses, "finished", WAIT);
    assert_eq!(
        (&two["episode"], &two["outcome"]),
        (&2.into(), &"unlabeled".into())
    );

    let output = child.output_within(Duration::from_secs(30));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("3 episodes recorded in ") && stderr.contains("; 2 kept"),
        "{stderr}"
    );
    assert!(out.join("discarded/episode_000000.mcap").exists());
    for (i, task, label) in [
        (1, "first task", "success"),
        (2, "second task", "unlabeled"),
    ] {
        let path = out.join(format!("episode_00000{i}.mcap"));
        let meta = episode_metadata(&path);
        assert_eq!(
            (meta["task"].as_str(), meta["outcome"].as_str()),
            (task, label)
        );
        let d: f64 = meta["duration_s"].parse().unwrap();
        assert!((0.95..1.6).contains(&d), "episode {i}: {d} s");
    }
    sim.stop();
}
