//! Normalization from meta/stats.json: every mode round-trips through the loader's normalizer,
//! and a batch's state and action, un-normalized, equal the values stored in the Parquet files
//! (read here with the parquet crate, not through the loader) — for our fixtures and for
//! LeRobot's own example dataset.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::HashMap;
use std::path::Path;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Int64Type};
use arrow_array::Array;
use common::Fixture;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use scaledp_datasets::{LoaderOptions, Norm};

/// (episode, frame) → the row's values of `column`, from every data file under `root`.
fn raw(root: &Path, column: &str) -> HashMap<(i64, i64), Vec<f32>> {
    let mut out = HashMap::new();
    let mut files: Vec<_> = std::fs::read_dir(root.join("data/chunk-000"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    for f in files {
        let reader = ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(f).unwrap())
            .unwrap()
            .build()
            .unwrap();
        for b in reader {
            let b = b.unwrap();
            let ep = b
                .column_by_name("episode_index")
                .unwrap()
                .as_primitive::<Int64Type>()
                .clone();
            let fr = b
                .column_by_name("frame_index")
                .unwrap()
                .as_primitive::<Int64Type>()
                .clone();
            let col = b.column_by_name(column).unwrap();
            for i in 0..b.num_rows() {
                let row = match col.data_type() {
                    arrow_schema::DataType::FixedSizeList(..) => col.as_fixed_size_list().value(i),
                    _ => col.as_list::<i32>().value(i),
                };
                let v = row.as_primitive::<Float32Type>().values().to_vec();
                out.insert((ep.value(i), fr.value(i)), v);
            }
        }
    }
    out
}

/// Equal up to f32 rounding of values whose normalization spans `scale` (the fixtures encode
/// episode·1000 + frame, so a wrong row is off by at least 0.125).
fn close(a: f32, b: f32, scale: f32) -> bool {
    (a - b).abs() <= 1e-6 * (scale + b.abs()) + 1e-6
}

/// The largest magnitude in a feature's stats.json min / max.
fn scale_of(location: &Path, feature: &str) -> f32 {
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(location.join("meta/stats.json")).unwrap()).unwrap();
    ["min", "max"]
        .iter()
        .flat_map(|k| {
            stats[feature][*k]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap().abs() as f32)
        })
        .fold(0.0, f32::max)
}

/// Every batch's state (obs step t) and action (step 0 is frame t when not padded),
/// un-normalized, equals the stored values.
fn check_against_parquet(location: &Path, state: Norm, action: Norm) -> usize {
    let mut l = LoaderOptions::default()
        .obs_horizon(2)
        .action_chunk(3)
        .state_norm(state)
        .action_norm(action)
        .batch_size(6)
        .open(location.to_str().unwrap())
        .unwrap();
    let (raw_s, raw_a) = (raw(location, "observation.state"), raw(location, "action"));
    let norm = l.normalizer().clone();
    let (ss, sa) = (
        scale_of(location, "observation.state"),
        scale_of(location, "action"),
    );
    let mut checked = 0;
    while let Some(b) = l.next_batch() {
        let mut b = b.unwrap();
        if action == Norm::MinMax {
            assert!(
                b.action
                    .iter()
                    .all(|v| (-1.0 - 1e-5..=1.0 + 1e-5).contains(v)),
                "min-max in [-1, 1]"
            );
        }
        norm.unnormalize_state(&mut b.state);
        norm.unnormalize_action(&mut b.action);
        for s in 0..b.len {
            let key = (b.episode_index[s], b.frame_index[s]);
            let st = &b.state[(s * 2 + 1) * b.state_dim..(s * 2 + 2) * b.state_dim];
            assert!(
                st.iter().zip(&raw_s[&key]).all(|(a, b)| close(*a, *b, ss)),
                "state {key:?}: {st:?} vs {:?}",
                raw_s[&key]
            );
            let ac = &b.action[s * 3 * b.action_dim..(s * 3 + 1) * b.action_dim];
            assert!(
                ac.iter().zip(&raw_a[&key]).all(|(a, b)| close(*a, *b, sa)),
                "action {key:?}: {ac:?} vs {:?}",
                raw_a[&key]
            );
            checked += 1;
        }
    }
    checked
}

#[test]
fn batches_unnormalize_to_the_stored_values_in_every_mode() {
    let ds = common::write(&Fixture {
        list_vectors: true,
        ..Fixture::default()
    });
    let total: usize = ds.fixture.lens.iter().sum();
    for (s, a) in [
        (Norm::MeanStd, Norm::MinMax),
        (Norm::MinMax, Norm::MeanStd),
        (Norm::None, Norm::None),
    ] {
        assert_eq!(check_against_parquet(&ds.root, s, a), total);
    }
}

#[test]
fn lerobot_example_dataset_loads_and_unnormalizes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/lerobot_v3_example");
    assert_eq!(
        check_against_parquet(&root, Norm::MeanStd, Norm::MinMax),
        24
    );
    let mut l = LoaderOptions::default()
        .batch_size(4)
        .open(root.to_str().unwrap())
        .unwrap();
    let info = l.info().clone();
    assert_eq!(info.cameras, ["observation.images.cam_high"]);
    assert_eq!((info.width, info.height, info.fps), (320, 240, 10.0));
    assert_eq!(
        info.state_names,
        ["x", "y", "z", "roll", "pitch", "yaw", "gripper"]
    );
    let b = l.next_batch().unwrap().unwrap();
    assert_eq!(b.images.len(), 4 * 2 * 3 * 240 * 320);
}

#[test]
fn normalizer_round_trips_and_matches_the_formulas() {
    let ds = common::write(&Fixture::default());
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ds.root.join("meta/stats.json")).unwrap()).unwrap();
    let stat =
        |f: &str, s: &str| -> Vec<f64> { serde_json::from_value(stats[f][s].clone()).unwrap() };
    let x: Vec<f32> = vec![0.5, -3.0, 1234.0, 7.25, 0.0, 99.0]; // two rows of 3 state values
    for mode in [Norm::MinMax, Norm::MeanStd, Norm::None] {
        let l = LoaderOptions::default()
            .state_norm(mode)
            .action_norm(mode)
            .open(&ds.location())
            .unwrap();
        let n = l.normalizer();
        let mut y = x.clone();
        n.normalize_state(&mut y);
        for (i, (&xi, &yi)) in x.iter().zip(&y).enumerate() {
            let d = i % 3;
            let want = match mode {
                Norm::MinMax => {
                    let (lo, hi) = (
                        stat("observation.state", "min")[d],
                        stat("observation.state", "max")[d],
                    );
                    if hi - lo >= 1e-4 {
                        2.0 * (f64::from(xi) - lo) / (hi - lo) - 1.0
                    } else {
                        f64::from(xi) - lo // a constant dimension is only centred
                    }
                }
                Norm::MeanStd => {
                    let (m, s) = (
                        stat("observation.state", "mean")[d],
                        stat("observation.state", "std")[d],
                    );
                    if s >= 1e-4 {
                        (f64::from(xi) - m) / (s + 1e-8)
                    } else {
                        f64::from(xi) - m
                    }
                }
                Norm::None => f64::from(xi),
            };
            assert!(
                (f64::from(yi) - want).abs() <= 1e-5 * want.abs().max(1.0),
                "{mode:?} {i}: {yi} vs {want}"
            );
        }
        n.unnormalize_state(&mut y);
        let (ss, sa) = (
            scale_of(&ds.root, "observation.state"),
            scale_of(&ds.root, "action"),
        );
        assert!(
            y.iter().zip(&x).all(|(a, b)| close(*a, *b, ss)),
            "{mode:?}: {y:?}"
        );
        let a: Vec<f32> = vec![-5.0, 2.5, -1001.0, 0.0];
        let mut z = a.clone();
        n.normalize_action(&mut z);
        if mode != Norm::None {
            assert_ne!(z, a);
        }
        n.unnormalize_action(&mut z);
        assert!(
            z.iter().zip(&a).all(|(p, q)| close(*p, *q, sa)),
            "{mode:?}: {z:?}"
        );
    }
}
