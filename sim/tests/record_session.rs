//! A recording session over time: the disk guard (a start refused when the disk has no room for
//! the episode; an episode ended, whole, before the disk fills, the ones before it kept), and a
//! timed, attended session driven by the pilot with Zenoh control words in both phases (a
//! discard while recording, a label and a new task in the reset): the discarded episode does not
//! count.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use scaledp_recorder::{Command, Event, FreeSpace, Label, Phase, Pilot, Plan};
use scaledp_schema::EpisodeMetadata;
use zenoh::Wait;

use crate::record_rig::{next, records, rigs, start, stored_verdict, wait_live, Side};

#[test]
fn the_disk_guard_refuses_a_start_without_room_and_ends_an_episode_before_the_disk_fills() {
    let (rig, sim_rig) = rigs();
    let dir = tempfile::tempdir().unwrap();
    let free = Arc::new(AtomicU64::new(100_000_000_000));
    let f = free.clone();
    let (recorder, sim, _) = start(&rig, &sim_rig, dir.path(), |o| {
        o.free_space(FreeSpace::new(move |_| Ok(f.load(Ordering::Relaxed))))
            .episode_time(Some(30.0))
    });
    let _side = Side::publish(recorder.session(), Arc::new(AtomicBool::new(true)));
    wait_live(&recorder, &[]);
    std::thread::sleep(Duration::from_millis(1500));

    // No room for 30 s of these streams (about 0.5 MB/s) in 8 MB: refused, with the figures.
    free.store(8_000_000, Ordering::Relaxed);
    recorder.send(Command::Start);
    let refusal = next(&recorder, |e| match e {
        Event::Refused { reason, force, .. } => Some((reason, force)),
        Event::Started { .. } => panic!("started without room"),
        _ => None,
    });
    assert!(!refusal.1, "a full disk is not forced");
    assert!(
        refusal
            .0
            .starts_with("episode 0 not started: it needs about ")
            && refusal.0.contains("(30 s, the episode time, at ")
            && refusal.0.ends_with("has 8 MB free"),
        "{}",
        refusal.0
    );

    // Room again: episode 0 records and is kept.
    free.store(100_000_000_000, Ordering::Relaxed);
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_secs(1));
    recorder.send(Command::Stop(Label::Success));
    let first = next(&recorder, |e| match e {
        Event::Finished(r) => Some(r),
        _ => None,
    });
    assert_eq!((first.index, first.cut.as_deref()), (0, None));

    // The disk fills while episode 1 records: it ends, finished and readable, naming its file.
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_millis(800));
    let t0 = Instant::now();
    free.store(10_000_000, Ordering::Relaxed);
    let mut low = None;
    let cut = next(&recorder, |e| match e {
        Event::Finished(r) => Some(r),
        Event::DiskLow(line) => {
            low = Some(line);
            None
        }
        Event::Failed { error, .. } => panic!("{error}"),
        _ => None,
    });
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
    assert_eq!(cut.index, 1);
    let line = cut.cut.clone().expect("ended by the disk guard");
    assert!(
        line.contains("episode_000001.mcap.partial: ended early, the disk is full"),
        "{line}"
    );
    assert!(cut.warnings.contains(&line));
    assert!(low.is_some_and(|l| l.contains("min of recording left")));
    assert!(cut.summary.path.ends_with("episode_000001.mcap"));
    assert_eq!(stored_verdict(&cut.summary.path), cut.verdict);
    // Episode 0 is untouched; nothing starts until there is room.
    assert_eq!(stored_verdict(&first.summary.path), first.verdict);
    recorder.send(Command::Start);
    let refused = next(&recorder, |e| match e {
        Event::Refused { reason, .. } => Some(reason),
        Event::Started { .. } => panic!("started on a full disk"),
        _ => None,
    });
    assert!(refused.starts_with("episode 2 not started"), "{refused}");
    let t = Instant::now();
    recorder.finish().unwrap();
    assert!(t.elapsed() < Duration::from_secs(10));
    sim.stop();
}

/// The `EpisodeMetadata` of an episode file's end record.
fn metadata(path: &std::path::Path) -> EpisodeMetadata {
    EpisodeMetadata::from_record(&records(path)[scaledp_schema::episode::END_RECORD]).unwrap()
}

#[test]
fn a_timed_attended_session_takes_control_words_in_both_phases_and_discards_do_not_count() {
    let (rig, sim_rig) = rigs();
    let dir = tempfile::tempdir().unwrap();
    let (recorder, sim, prefix) = start(&rig, &sim_rig, dir.path(), |o| o.check_topics(true));
    let _side = Side::publish(recorder.session(), Arc::new(AtomicBool::new(true)));
    wait_live(&recorder, &[]);
    let mut pilot = Pilot::new(Plan {
        episodes: Some(2),
        episode_s: Some(1.0),
        reset_s: 0.8,
        attended: true,
        confirm: false,
    });
    let control = |word: &str| {
        let key = format!("{prefix}/control");
        recorder
            .session()
            .put(key, word.to_string())
            .wait()
            .unwrap();
    };
    let mut started = Vec::new();
    let mut ended = Vec::new();
    let mut phases = Vec::new();
    let (mut discarded, mut labelled, mut retasked) = (false, false, false);
    let t0 = Instant::now();
    while pilot.done().is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(40),
            "{:?}",
            pilot.phase()
        );
        for e in pilot.poll(&recorder) {
            match e {
                Event::Started { index, .. } => started.push((index, Instant::now())),
                Event::Ended { index, verdict } => ended.push((index, verdict)),
                Event::Refused { reason, .. } => eprintln!("{reason}"),
                Event::Failed { error, .. } => panic!("{error}"),
                _ => {}
            }
        }
        let phase = pilot.phase();
        match &phase {
            // A discard over Zenoh 0.4 s into the first episode.
            Phase::Recording { index: 0, .. }
                if !discarded && started[0].1.elapsed() > Duration::from_millis(400) =>
            {
                control("discard");
                discarded = true;
            }
            // Episode 1 labelled in its reset, and a new task for the next.
            Phase::Reset { held: Some(1), .. } if !labelled => {
                control("success");
                control("task put the blue cube on the red square");
                labelled = true;
            }
            Phase::Reset { held: None, .. } if labelled && !retasked => retasked = true,
            _ => {}
        }
        if phases.last() != Some(&std::mem::discriminant(&phase)) {
            phases.push(std::mem::discriminant(&phase));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(pilot.done(), Some("2 episodes kept"));
    assert_eq!(pilot.kept(), 2);
    let indices: Vec<u64> = started.iter().map(|s| s.0).collect();
    assert_eq!(
        indices,
        [0, 1, 2],
        "the discarded episode is recorded again"
    );
    assert_eq!(
        ended.iter().map(|e| e.0).collect::<Vec<_>>(),
        [1, 2],
        "episodes 1 and 2 ended on their timer, held for a label"
    );
    assert!(retasked);
    let out = dir.path();
    assert!(out.join("discarded/episode_000000.mcap").exists());
    let one = metadata(&out.join("episode_000001.mcap"));
    let two = metadata(&out.join("episode_000002.mcap"));
    assert_eq!(one.label, Some(Label::Success));
    assert_eq!(two.label, Some(Label::Unlabeled));
    assert_eq!(one.task, "put the red cube on the green square");
    assert_eq!(two.task, "put the blue cube on the red square");
    for (i, (_, verdict)) in ended.iter().enumerate() {
        let path = out.join(format!("episode_{:06}.mcap", i + 1));
        assert_eq!(&stored_verdict(&path), verdict);
        let d = metadata(&path).duration_s.unwrap();
        assert!((0.95..1.6).contains(&d), "episode {}: {d} s", i + 1);
    }
    // Recording, reset and recording again follow one another.
    assert!(phases.len() >= 5, "{phases:?}");
    recorder.finish().unwrap();
    sim.stop();
}
