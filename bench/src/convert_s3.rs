//! The object-storage and floor rows of `scaledp bench convert`.
//!
//! - **S3**: the same recordings uploaded to a loopback moto server (the tests' venv; no IAM
//!   auth) and converted bucket to bucket by a `scaledp convert` child (ranged reads in,
//!   staged multipart uploads out). moto is a Python server on the same cores, so this row is a
//!   lower bound of what a real endpoint gives.
//! - **Floor**: [`scaledp_converter::floor`] in this process over the local recordings: every
//!   chunk decompressed and each frame the output keeps resized and encoded, nothing else. The
//!   converter's frames/s over the floor's is how close it is to its limit on this machine.

use std::path::Path;
use std::process::Command as Process;

use anyhow::{bail, Context, Result};
use scaledp_converter::images::EncodeSpec;
use scaledp_store::{Bucket, ObjectUrl, S3Settings};
use scaledp_testkit::{cpu_seconds, measure, workspace_from_current_dir, Measured, Moto, Venv};

/// What a route did, for a row: frames (dataset rows), output bytes, and the measurement.
pub(crate) struct Route {
    pub m: Measured,
    pub frames: u64,
    pub output_bytes: u64,
}

fn url(key: &str) -> ObjectUrl {
    ObjectUrl {
        bucket: "data".into(),
        key: key.into(),
    }
}

/// Uploads `recordings` to a loopback moto and converts them bucket to bucket; Err says why
/// the row could not run.
pub(crate) fn s3_route(recordings: &Path, jobs: usize, venv: &Venv) -> Result<Route> {
    let root = workspace_from_current_dir().context("the S3 row runs moto from the checkout")?;
    let python = venv.python(None, Some(&root))?;
    let tmp = tempfile::tempdir()?;
    let moto = Moto::start(&python, &root, &tmp.path().join("moto.log"))?;
    let setup = Process::new(&python)
        .arg(root.join("tests/py/s3_setup.py"))
        .arg(&moto.endpoint)
        .arg("--open")
        .output()
        .context("running tests/py/s3_setup.py")?;
    if !setup.status.success() {
        bail!("s3_setup.py: {}", String::from_utf8_lossy(&setup.stderr));
    }
    let settings = S3Settings {
        endpoint: Some(moto.endpoint.clone()),
        region: Some("us-east-1".into()),
        keys: Some(("testing".into(), "testing".into(), None)),
        credentials_from: "moto's test key".into(),
    };
    let bucket = Bucket::connect_with("data", &settings)?;
    for e in std::fs::read_dir(recordings)?.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        bucket.upload(&e.path(), &url(&format!("bench/rec/{name}")))?;
    }
    let exe = std::env::current_exe().context("locating the scaledp executable")?;
    let mut convert = Process::new(exe);
    convert
        .args([
            "convert",
            "s3://data/bench/rec/",
            "--out",
            "s3://data/bench/ds",
        ])
        .args([
            "--jobs",
            &jobs.to_string(),
            "--unlabeled",
            "keep",
            "--no-depth",
        ])
        .env("AWS_ENDPOINT_URL", &moto.endpoint)
        .env("AWS_ACCESS_KEY_ID", "testing")
        .env("AWS_SECRET_ACCESS_KEY", "testing")
        .env("AWS_REGION", "us-east-1");
    let m = measure(convert, None).context("running scaledp convert on S3")?;
    if !m.status.success() {
        bail!(
            "scaledp convert exited with {}: {}",
            m.status,
            m.stderr.last().map_or("", String::as_str)
        );
    }
    let info = bucket
        .get(&url("bench/ds/meta/info.json"))?
        .context("no meta/info.json at s3://data/bench/ds")?;
    let info: serde_json::Value = serde_json::from_slice(&info)?;
    let frames = info["total_frames"].as_u64().context("no total_frames")?;
    let output_bytes = bucket
        .list(&url("bench/ds/data/"))?
        .iter()
        .map(|o| o.size)
        .sum();
    Ok(Route {
        m,
        frames,
        output_bytes,
    })
}

/// The floor pass over the local recordings: frames in dataset rows (encoded images over
/// `cameras`), wall and CPU seconds of this process.
pub(crate) fn floor_route(
    recordings: &Path,
    cameras: usize,
    stride: usize,
    jobs: usize,
) -> Result<(f64, Option<f64>, u64)> {
    let inputs = scaledp_converter::collect_inputs(&[recordings.to_path_buf()])?;
    let spec = EncodeSpec {
        width: 320,
        height: 240,
        quality: 90,
        raw: false,
    };
    let cpu_before = cpu_seconds(std::process::id());
    let report = scaledp_converter::floor(&inputs, stride, &spec, jobs)?;
    let cpu = cpu_seconds(std::process::id())
        .zip(cpu_before)
        .map(|(a, b)| a - b);
    Ok((report.seconds, cpu, report.frames / cameras.max(1) as u64))
}
