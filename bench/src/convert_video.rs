//! `bench convert --video CODEC…`: the same recordings converted again with the cameras stored
//! as video features, beside JPEG images at several qualities. Each row gives the converter's
//! frames/s, the dataset's size and its pictures' PSNR against a near-lossless reference (JPEG
//! q100 of the same resized frames, read back through our loader), so sizes compare at equal
//! visual quality: the JPEG size at a video's PSNR is interpolated between the JPEG rows.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use scaledp_datasets::LoaderOptions;
use scaledp_testkit::Measured;

use crate::convert_run::scaledp_convert as convert;
use crate::disk::dir_bytes;

/// JPEG qualities converted beside the videos (q100 is the reference).
const JPEG_QUALITIES: [u8; 3] = [50, 75, 90];

/// One conversion of the recordings.
struct Row {
    name: String,
    m: Measured,
    frames: u64,
    bytes: u64,
    psnr_db: f64,
}

/// Every frame of every camera of `dataset`, keyed by (episode, frame, camera).
type Pictures = BTreeMap<(i64, i64, usize), Vec<u8>>;

/// The pictures of `dataset` as our loader returns them (RGB, channel-first per camera).
fn pictures(dataset: &Path) -> Result<(Pictures, u64)> {
    let info_path = dataset.join("meta/info.json");
    let info: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&info_path).with_context(|| format!("reading {}", info_path.display()))?,
    )?;
    let cameras: Vec<String> = info["features"]
        .as_object()
        .map(|f| {
            f.keys()
                .filter(|k| k.starts_with("observation.images."))
                .cloned()
                .collect()
        })
        .unwrap_or_default();
    let mut loader = LoaderOptions::default()
        .obs_horizon(1)
        .action_chunk(1)
        .shuffle(false)
        .batch_size(64)
        .cameras(cameras.clone())
        .open(&dataset.to_string_lossy())?;
    let mut out = Pictures::new();
    while let Some(b) = loader.next_batch().transpose()? {
        let per = b.images.len() / (b.len * cameras.len()).max(1);
        for i in 0..b.len {
            for c in 0..cameras.len() {
                let at = (i * cameras.len() + c) * per;
                out.insert(
                    (b.episode_index[i], b.frame_index[i], c),
                    b.images[at..at + per].to_vec(),
                );
            }
        }
    }
    let frames = info["total_frames"].as_u64().unwrap_or(0);
    Ok((out, frames))
}

/// PSNR (dB) of `test` against `reference` over every picture both hold.
fn psnr(reference: &Pictures, test: &Pictures) -> Result<f64> {
    let (mut sum, mut n) = (0f64, 0u64);
    for (k, r) in reference {
        let t = test.get(k).with_context(|| {
            format!(
                "no picture for episode {} frame {} camera {}",
                k.0, k.1, k.2
            )
        })?;
        for (a, b) in r.iter().zip(t) {
            let d = f64::from(*a) - f64::from(*b);
            sum += d * d;
        }
        n += r.len() as u64;
    }
    if n == 0 {
        bail!("no pictures to compare");
    }
    let mse = sum / n as f64;
    Ok(if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    })
}

/// Converts `recordings` as JPEG q100 (the reference), JPEG at [`JPEG_QUALITIES`] and video in
/// each of `codecs`, under `root`, and prints the table.
pub fn run(
    exe: &Path,
    recordings: &Path,
    root: &Path,
    jobs: usize,
    codecs: &[String],
) -> Result<()> {
    let dir = |name: &str| -> PathBuf { root.join(format!("dataset-{name}")) };
    convert(
        exe,
        recordings,
        &dir("q100"),
        jobs,
        &["--jpeg-quality", "100"],
    )?;
    let (reference, _) = pictures(&dir("q100"))?;
    let mut rows = Vec::new();
    let variants = JPEG_QUALITIES
        .iter()
        .map(|q| {
            (
                format!("jpeg q{q}"),
                vec!["--jpeg-quality".to_string(), q.to_string()],
            )
        })
        .chain(
            codecs
                .iter()
                .map(|c| (format!("video {c}"), vec!["--video".to_string(), c.clone()])),
        );
    for (name, extra) in variants {
        let out = dir(&name.replace(' ', "-"));
        let extra: Vec<&str> = extra.iter().map(String::as_str).collect();
        let m = convert(exe, recordings, &out, jobs, &extra)?;
        let (pics, frames) = pictures(&out)?;
        let bytes = dir_bytes(&out.join("data"))? + dir_bytes(&out.join("videos"))?;
        rows.push(Row {
            psnr_db: psnr(&reference, &pics)?,
            name,
            m,
            frames,
            bytes,
        });
    }
    println!(
        "cameras as video: PSNR against JPEG q100 of the same resized frames, read back by our loader"
    );
    println!(
        "{:<16} {:>7} {:>8} {:>9} {:>10} {:>12} {:>8} {:>12}",
        "dataset",
        "frames",
        "seconds",
        "frames/s",
        "output MB",
        "bytes/frame",
        "PSNR dB",
        "peak RSS MB"
    );
    for r in &rows {
        println!(
            "{:<16} {:>7} {:>8.2} {:>9.1} {:>10.2} {:>12.0} {:>8.2} {:>12}",
            r.name,
            r.frames,
            r.m.wall_s,
            r.frames as f64 / r.m.wall_s,
            r.bytes as f64 / 1e6,
            r.bytes as f64 / r.frames.max(1) as f64,
            r.psnr_db,
            r.m.peak_rss
                .map_or("n/a".into(), |b| format!("{:.0}", b as f64 / 1e6)),
        );
    }
    let jpeg: Vec<&Row> = rows.iter().filter(|r| r.name.starts_with("jpeg")).collect();
    for v in rows.iter().filter(|r| r.name.starts_with("video")) {
        match jpeg_bytes_at(&jpeg, v.psnr_db) {
            Some(b) => println!(
                "{}: {:.2} MB; JPEG at the same PSNR ({:.2} dB, interpolated): {:.2} MB, {:.1}× the video",
                v.name,
                v.bytes as f64 / 1e6,
                v.psnr_db,
                b / 1e6,
                b / v.bytes as f64
            ),
            None => println!(
                "{}: {:.2} MB at {:.2} dB, outside the JPEG rows' PSNR range: no equal-quality JPEG size",
                v.name,
                v.bytes as f64 / 1e6,
                v.psnr_db
            ),
        }
    }
    Ok(())
}

/// The JPEG dataset size at `psnr`, interpolated linearly between the two JPEG rows around it.
fn jpeg_bytes_at(jpeg: &[&Row], psnr: f64) -> Option<f64> {
    let mut pts: Vec<(f64, f64)> = jpeg.iter().map(|r| (r.psnr_db, r.bytes as f64)).collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.windows(2).find_map(|w| {
        let ((p0, b0), (p1, b1)) = (w[0], w[1]);
        (p0 <= psnr && psnr <= p1 && p1 > p0).then(|| b0 + (b1 - b0) * (psnr - p0) / (p1 - p0))
    })
}
