//! `.rrd` files of a recording, a converted dataset and foreign bags, read back with the
//! `rerun-sdk` Python package (`tests/py/read_rrd.py`, pinned in tests/py/requirements.txt):
//! entity paths, every camera frame / dataset frame exactly once, scalars equal to the source.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use scaledp_converter::{convert, ConvertOptions, InMemory};
use scaledp_schema::msg::JointState;
use scaledp_schema::{Rig, RosMessage};
use scaledp_testkit::{make_bags, run_python};
use scaledp_viewer::{view, Error, Prediction, Target, ViewOptions};
use serde_json::Value;

/// Start of the first synthetic episode (ns).
const T0: u64 = 1_700_000_000_000_000_000;

/// The Franka rig with its real topics, encodings and rates, but 64×48 images.
fn small_franka() -> Rig {
    Rig::builtin("franka_2zed").unwrap().with_image_size(64, 48)
}

fn synth(path: &Path, rig: &Rig, seed: u64, seconds: f64) {
    scaledp_sim::write_episode(
        path,
        rig,
        seed,
        seconds,
        T0 + seed * 100_000_000_000,
        "stack the cubes",
        &mut |_, _, _, _| {},
    )
    .unwrap();
}

fn save(paths: &[&Path], opts: ViewOptions, out: &Path) -> scaledp_viewer::Summary {
    let paths: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    view(&paths, opts, &Target::Save(out.into())).unwrap()
}

fn read(rrd: &Path) -> Vec<Value> {
    let v = run_python("read_rrd.py", &[rrd]);
    v["recordings"].as_array().unwrap().clone()
}

fn entity<'a>(rec: &'a Value, path: &str) -> &'a Value {
    rec["entities"].get(path).unwrap_or_else(|| {
        panic!(
            "no entity {path}; have {:?}",
            rec["entities"]
                .as_object()
                .unwrap()
                .keys()
                .collect::<Vec<_>>()
        )
    })
}

fn rows(rec: &Value, path: &str) -> Vec<Value> {
    entity(rec, path)["rows"].as_array().unwrap().clone()
}

/// (timeline value, scalars) of every row of a scalar entity, sorted by the timeline.
fn scalars(rec: &Value, path: &str, timeline: &str) -> Vec<(i64, Vec<f64>)> {
    let mut out: Vec<(i64, Vec<f64>)> = rows(rec, path)
        .iter()
        .map(|r| {
            let t = r[timeline]
                .as_i64()
                .unwrap_or_else(|| panic!("{path}: row without {timeline}: {r}"));
            let v = r["Scalars:scalars"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::NAN))
                .collect();
            (t, v)
        })
        .collect();
    out.sort_by(|a, b| {
        a.0.cmp(&b.0)
            .then(a.1.partial_cmp(&b.1).unwrap_or(std::cmp::Ordering::Equal))
    });
    out
}

/// Sorted values of `timeline` of every row of an image entity.
fn image_times(rec: &Value, path: &str, timeline: &str) -> Vec<i64> {
    let mut t: Vec<i64> = rows(rec, path)
        .iter()
        .filter(|r| r.get("Image:buffer").is_some() || r.get("EncodedImage:blob").is_some())
        .map(|r| r[timeline].as_i64().unwrap())
        .collect();
    t.sort_unstable();
    t
}

fn no_leftovers(out: &Path) {
    let mut partial = out.as_os_str().to_os_string();
    partial.push(".partial");
    assert!(!out.exists(), "{} was written", out.display());
    assert!(!Path::new(&partial).exists(), "a partial file was left");
}

/// Converts `inputs` into a dataset at `out` with the converter library.
fn convert_dataset(inputs: &[PathBuf], out: &Path) {
    let opts = scaledp_converter::JobOptions::default()
        // Synthetic episodes: no labels, and no depth (the simulator writes the training
        // streams only).
        .convert(ConvertOptions::default().size(64, 48).depth(false))
        .unlabeled(scaledp_converter::Unlabeled::Keep)
        .jobs(1);
    let results = scaledp_converter::run(inputs, out, &opts, &|_| {}).unwrap();
    assert!(
        results
            .iter()
            .all(|(_, o)| matches!(o, scaledp_converter::InputResult::Converted(_))),
        "{results:?}"
    );
}

mod bags_and_faults;
mod dataset;
mod recording;
