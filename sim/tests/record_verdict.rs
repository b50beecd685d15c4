//! Each episode's verdict, live: a camera that stops mid-episode is named, one that stalls
//! makes convert reject the episode, one silent before the start holds the start back until
//! the operator forces it (and the episode says so); each time the verdict stored in the file is
//! the one reported, and `scaledp convert`'s rules decide the same on that file, reason for
//! reason.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use scaledp_recorder::{Command, EpisodeReport, Event, Label, STARTED_WITH_MISSING_TOPICS};

use crate::record_rig::{
    convert_reason, next, records, rigs, start, stored_verdict, wait_live, Side, SIDE,
};

fn finished(recorder: &scaledp_recorder::Recorder) -> EpisodeReport {
    next(recorder, |e| match e {
        Event::Finished(r) => Some(r),
        Event::Failed { error, .. } => panic!("{error}"),
        _ => None,
    })
}

/// The verdict reported, the one stored and convert's decision agree.
fn assert_agrees(r: &EpisodeReport) {
    let path = &r.summary.path;
    assert_eq!(stored_verdict(path), r.verdict, "{}", path.display());
    assert_eq!(
        convert_reason(path),
        r.verdict.reason,
        "{}: the recorder's verdict and convert disagree",
        path.display()
    );
    assert_eq!(r.verdict.accepted, r.verdict.reason.is_none());
}

fn sleep(s: f64) {
    std::thread::sleep(Duration::from_secs_f64(s));
}

#[test]
fn a_camera_that_stops_is_named_one_that_stalls_rejects_and_convert_agrees() {
    let (rig, sim_rig) = rigs();
    let dir = tempfile::tempdir().unwrap();
    let (recorder, sim, _) = start(&rig, &sim_rig, dir.path(), |o| o);
    let on = Arc::new(AtomicBool::new(true));
    let side = Side::publish(recorder.session(), on.clone());
    wait_live(&recorder, &[]);

    // Stops after 1 s of 2.5: convert keeps the first second, the verdict names the camera.
    recorder.send(Command::Start);
    sleep(1.0);
    on.store(false, Ordering::Relaxed);
    sleep(1.5);
    recorder.send(Command::Stop(Label::Success));
    let r = finished(&recorder);
    let stopped: Vec<&String> = r
        .verdict
        .warnings
        .iter()
        .filter(|w| w.starts_with(&format!("{SIDE} stopped ")))
        .collect();
    assert_eq!(stopped.len(), 1, "{:?}", r.verdict);
    assert!(r.verdict.line().contains(stopped[0].as_str()));
    assert_agrees(&r);
    if r.verdict.accepted {
        assert!(
            r.verdict.kept_s < r.verdict.recorded_s - 1.0,
            "{:?}",
            r.verdict
        );
    }

    // Stalls for a second in the middle: a tenth of the ticks have a stale frame of it.
    on.store(true, Ordering::Relaxed);
    sleep(0.5);
    recorder.send(Command::Start);
    sleep(0.8);
    on.store(false, Ordering::Relaxed);
    sleep(1.0);
    on.store(true, Ordering::Relaxed);
    sleep(0.8);
    recorder.send(Command::Stop(Label::Success));
    let r = finished(&recorder);
    let reason = r
        .verdict
        .reason
        .clone()
        .expect("a stalled camera is rejected");
    assert!(
        reason.contains("ticks have a stale camera frame or a joint gap") && reason.contains(SIDE),
        "{reason}"
    );
    assert!(r.verdict.line().starts_with("convert would reject it: "));
    assert_agrees(&r);
    drop(side);
    recorder.finish().unwrap();
    sim.stop();
}

#[test]
fn a_silent_camera_holds_the_start_until_forced_and_the_episode_says_so() {
    let (rig, sim_rig) = rigs();
    let dir = tempfile::tempdir().unwrap();
    let (recorder, sim, _) = start(&rig, &sim_rig, dir.path(), |o| o.check_topics(true));
    wait_live(&recorder, &[SIDE]);
    // A second and a half of rates measured.
    sleep(1.5);
    let silent = format!("{SIDE}: nothing received");
    assert!(recorder.liveness().problems().contains(&silent));

    recorder.send(Command::Start);
    let (reason, problems, force) = next(&recorder, |e| match e {
        Event::Refused {
            reason,
            problems,
            force,
        } => Some((reason, problems, force)),
        Event::Started { .. } => panic!("started with {SIDE} silent"),
        _ => None,
    });
    assert!(force && problems.contains(&silent), "{problems:?}");
    assert!(
        reason.starts_with("episode 0 not started, topics not live: ") && reason.contains(&silent),
        "{reason}"
    );
    assert_eq!(recorder.status().episode, None);

    recorder.send(Command::ForceStart);
    sleep(1.0);
    recorder.send(Command::Stop(Label::Unlabeled));
    let r = finished(&recorder);
    assert_eq!(r.index, 0);
    assert!(r.started_with_missing_topics.contains(&silent));
    let end = &records(&r.summary.path)[scaledp_schema::episode::END_RECORD];
    let listed: Vec<String> = serde_json::from_str(&end[STARTED_WITH_MISSING_TOPICS]).unwrap();
    assert!(listed.contains(&silent), "{listed:?}");
    assert_eq!(
        r.verdict.reason.as_deref(),
        Some(format!("camera 'side' ({SIDE}) has no messages").as_str())
    );
    assert_agrees(&r);
    recorder.finish().unwrap();
    sim.stop();
}
