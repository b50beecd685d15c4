//! Tests of the alignment rules (`align.rs`).

use super::*;

fn grid(start_ms: u64, period_ms: f64, n: usize) -> Vec<u64> {
    (0..n)
        .map(|k| start_ms * 1_000_000 + (k as f64 * period_ms * 1e6) as u64)
        .collect()
}

#[test]
fn latest_frame_and_interpolation() {
    let cam = Stream::new("/cam", grid(0, 33.3, 31), Some(30.0));
    let joints = Stream::new("/joints", grid(0, 1.0, 1001), Some(1000.0));
    let a = align(
        std::slice::from_ref(&cam),
        std::slice::from_ref(&joints),
        10.0,
        1.5,
        0.0,
    )
    .unwrap();
    assert_eq!(a.report.ticks, 10);
    for (k, t) in a.ticks_ns.iter().enumerate() {
        let f = a.frames[k][0];
        assert!(cam.stamps_ns[f] <= *t && *t - cam.stamps_ns[f] < 34_000_000);
        let (i, j, w) = a.samples[k][0];
        let interp = joints.stamps_ns[i] as f64 * (1.0 - w) + joints.stamps_ns[j] as f64 * w;
        assert!((interp - *t as f64).abs() < 1.0);
    }
    assert_eq!(a.report.invalid, 0);
}

#[test]
fn synchronised_cameras_with_jitter_pick_the_same_capture() {
    // Two 30 fps cameras triggered together, each stamp off by up to ±0.4 ms; both first
    // stamps on the trigger, so a grid started there lies on the frame instants.
    let jittered = |sign: i64| -> Vec<u64> {
        grid(0, 100.0 / 3.0, 90)
            .into_iter()
            .enumerate()
            .map(|(k, s)| {
                let j = sign * [0i64, 400_000, -300_000, 100_000, -400_000][k % 5];
                (s as i64 + 1_000_000 + j) as u64
            })
            .collect()
    };
    let cams = [
        Stream::new("/a", jittered(1), Some(30.0)),
        Stream::new("/b", jittered(-1), Some(30.0)),
    ];
    let joints = Stream::new("/joints", grid(0, 1.0, 3001), Some(1000.0));
    let a = align(&cams, std::slice::from_ref(&joints), 10.0, 1.5, 0.0).unwrap();
    assert!(a.report.ticks >= 28, "{}", a.report.ticks);
    assert!(
        a.report.max_camera_skew_s < 0.001,
        "{} s",
        a.report.max_camera_skew_s
    );
    // Every tick takes the same capture (index) from both cameras, a quarter frame (8.3 ms)
    // old give or take the jitter.
    for (t, f) in a.ticks_ns.iter().zip(&a.frames) {
        assert_eq!(f[0], f[1]);
        let age = t - cams[0].stamps_ns[f[0]];
        assert!((7_900_000..=8_800_000).contains(&age), "{age} ns");
    }
}

#[test]
fn stale_frames_invalidate_and_gaps_are_counted() {
    let mut stamps = grid(0, 33.3, 61);
    stamps.drain(20..30); // a third of a second without frames
    let cam = Stream::new("/cam", stamps, Some(30.0));
    let joints = Stream::new("/joints", grid(0, 1.0, 2001), Some(1000.0));
    let e = align(
        std::slice::from_ref(&cam),
        std::slice::from_ref(&joints),
        10.0,
        1.5,
        0.0,
    )
    .unwrap_err();
    assert!(e.contains("stale camera frame"), "{e}");
    assert!(e.ends_with("(limit 0 %): /cam 3"), "{e}");
    let a = align(&[cam], &[joints], 10.0, 1.5, 0.2).unwrap();
    assert!(a.report.invalid >= 2);
    let cam_report = &a.report.streams[0];
    assert_eq!((cam_report.gaps, cam_report.dropped), (1, 10));
}

#[test]
fn joint_holes_up_to_a_tick_are_interpolated_and_wider_ones_are_named() {
    let cam = Stream::new("/cam", grid(0, 33.3, 61), Some(30.0));
    let with_hole = |from: usize, len: usize| {
        let mut stamps = grid(0, 1.0, 2001);
        stamps.drain(from..from + len);
        Stream::new("/joints", stamps, Some(1000.0))
    };
    // 80 ms without samples (a host stall): over 50 ms, but under a 10 Hz tick.
    let a = align(
        std::slice::from_ref(&cam),
        &[with_hole(1000, 79)],
        10.0,
        1.5,
        0.0,
    )
    .unwrap();
    assert_eq!(a.report.invalid, 0);
    // The same hole at 30 Hz ticks, and a 250 ms hole at 10 Hz, are not interpolated.
    let e = align(
        std::slice::from_ref(&cam),
        &[with_hole(1000, 79)],
        30.0,
        1.5,
        0.0,
    )
    .unwrap_err();
    assert!(e.ends_with("/joints 3"), "{e}");
    let e = align(&[cam], &[with_hole(1000, 249)], 10.0, 1.5, 0.0).unwrap_err();
    assert!(e.ends_with("/joints 3"), "{e}");
}

#[test]
fn missing_streams_are_errors() {
    let e = align(
        &[Stream::new("/cam", vec![], Some(30.0))],
        &[],
        10.0,
        1.5,
        0.1,
    )
    .unwrap_err();
    assert_eq!(e, "/cam has no messages");
}

#[test]
fn a_stamp_that_jumps_is_refused_before_allocating() {
    let mut stamps = grid(0, 33.3, 30);
    stamps.push(1_000_000_000_000_000_000); // 10^18 ns: ~32 years later
    let cam = Stream::new("/cam", stamps.clone(), Some(30.0));
    let joints = Stream::new("/joints", stamps, Some(30.0));
    let e = align(&[cam], &[joints], 10.0, 1.5, 1.0).unwrap_err();
    assert!(
        e.contains("a stamp jumps") && e.contains("31 messages"),
        "{e}"
    );
}
