//! `recover` keeps every chunk that was complete when the file was cut, and nothing broken.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;

use scaledp_recorder::{partial_path, recover, EpisodeOptions};
use scaledp_schema::rig::TopicSpec;

#[test]
fn every_complete_chunk_survives_any_cut() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("episode_000000.mcap");
    let topics: Vec<TopicSpec> = scaledp_schema::Rig::builtin("franka_2zed")
        .unwrap()
        .topics()
        .into_iter()
        .filter(|t| t.topic == "/franka/joint_states")
        .collect();
    let meta = BTreeMap::from([("task".to_string(), "t".to_string())]);
    let mut w = EpisodeOptions::new()
        .chunk_size(1 << 30)
        .create(&path, &topics, meta)
        .unwrap();
    let partial = partial_path(&path);
    // Ten flushes of ten messages: the file size after each flush is a safe cut point.
    let mut safe = vec![];
    for i in 0..100u64 {
        let mut data = scaledp_schema::CDR_LE_HEADER.to_vec();
        data.extend_from_slice(&(i as i32).to_le_bytes());
        data.extend_from_slice(&[7u8; 996]);
        w.write(0, 1_000 + i, 1_000 + i, &data).unwrap();
        if i % 10 == 9 {
            w.flush().unwrap();
            safe.push(std::fs::metadata(&partial).unwrap().len());
        }
    }
    let full = std::fs::read(&partial).unwrap();
    assert_eq!(full.len() as u64, *safe.last().unwrap());
    for cut in [
        full.len(),
        full.len() - 1,
        full.len() / 2,
        full.len() / 3 + 17,
        safe[0] as usize,
        100,
    ] {
        let cut_file = dir.path().join(format!("cut_{cut}.mcap.partial"));
        std::fs::write(&cut_file, &full[..cut]).unwrap();
        let out = dir.path().join(format!("cut_{cut}.mcap"));
        let s = recover(&cut_file, &out).unwrap();
        // A flush ends a chunk and then writes its message index; the chunk itself (and its
        // ten messages) is complete slightly before the recorded size, never after.
        let complete = safe.iter().filter(|&&n| n as usize <= cut).count() as u64;
        assert!(
            s.messages % 10 == 0 && (complete * 10..=(complete + 1) * 10).contains(&s.messages),
            "cut at {cut}: kept {} with {complete} complete chunks ({:?})",
            s.messages,
            s.stopped_at
        );
        // The result is a valid, finished MCAP with the messages in order.
        let bytes = std::fs::read(&out).unwrap();
        let msgs: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(msgs.len() as u64, s.messages);
        assert!(msgs
            .iter()
            .enumerate()
            .all(|(i, m)| m.log_time == 1_000 + i as u64));
        assert!(recover(&cut_file, &out).is_err(), "never overwrites");
    }
    drop(w);
}
