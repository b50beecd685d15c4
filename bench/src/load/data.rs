//! The datasets `scaledp bench load` reads, generated once into a cache directory and reused
//! while complete: the bimanual rig (2 × UR5 + Robotiq, 3 RealSense cameras) with the cameras
//! rendered by the simulator at 320×240 and at the control rate (10 Hz; the converter keeps one
//! frame per tick anyway), written as recorder-style episodes by `sim::synth` and
//! converted by the converter library (10 Hz, 320×240 JPEG q90), a few episodes at a time so
//! the raw recordings never pile up on disk. The larger dataset for the streaming run is the
//! generated one merged with itself. And the pure-decode measurement: the JPEGs of an epoch's
//! samples decoded with nothing else around them.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use arrow_array::cast::AsArray;
use arrow_array::{Array, Int64Array};
use indicatif::{ProgressBar, ProgressStyle};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use rayon::prelude::*;
use scaledp_converter::{ConvertOptions, JobOptions, Outcome};
use scaledp_schema::Rig;
use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;
use zune_jpeg::JpegDecoder;

use crate::convert::synthesize;

const RIG: &str = "bimanual_ur5_3rs";
const TASK: &str = "hand the cup from the left arm to the right";
const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;

/// What to generate.
pub(crate) struct DataSpec {
    /// Episodes.
    pub episodes: usize,
    /// Seconds per episode.
    pub seconds: f64,
    /// Threads for rendering and converting.
    pub jobs: usize,
}

/// The converter's file layout the cached datasets were written with: bump it when that
/// layout changes (2: a Parquet page per encoded frame), so stale caches are not measured.
const LAYOUT: u32 = 2;

fn name(spec: &DataSpec) -> String {
    format!("{RIG}-{}x{}s-layout{LAYOUT}", spec.episodes, spec.seconds)
}

/// The marker written beside a dataset once it is complete.
fn marker(cache: &Path, name: &str) -> PathBuf {
    cache.join(format!("{name}.complete.json"))
}

/// Whether `cache/name` was completed by the same recipe (`how`).
fn complete(cache: &Path, name: &str, how: &str) -> bool {
    let recipe = std::fs::read(marker(cache, name))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v["recipe"].as_str().map(str::to_string));
    recipe.as_deref() == Some(how) && cache.join(name).join("meta/info.json").is_file()
}

fn mark(cache: &Path, name: &str, how: &str, seconds: f64) -> Result<()> {
    let path = marker(cache, name);
    std::fs::write(
        &path,
        serde_json::json!({ "recipe": how, "seconds": seconds }).to_string(),
    )
    .with_context(|| format!("writing {}", path.display()))
}

fn bar(len: u64, what: &str) -> ProgressBar {
    let style = ProgressStyle::with_template(&format!(
        "{{spinner}} [{{elapsed_precise}}] {{bar:30}} {{pos}}/{{len}} {what} {{msg}}"
    ))
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    ProgressBar::new(len).with_style(style)
}

/// The generated dataset under `cache` (made if absent or incomplete) and how it was made.
pub(crate) fn ensure_dataset(cache: &Path, spec: &DataSpec) -> Result<(PathBuf, String)> {
    let name = name(spec);
    let dir = cache.join(&name);
    let how = format!(
        "{} episodes × {} s of {RIG} (3 RealSense cameras rendered by the simulator at {WIDTH}×{HEIGHT} rgb8 10 Hz, the control rate, 2 UR5 + Robotiq), written by sim::synth as recordings and converted by the converter library at 10 Hz into {WIDTH}×{HEIGHT} JPEG q90",
        spec.episodes, spec.seconds
    );
    if complete(cache, &name, &how) {
        return Ok((dir, format!("{how}; reused from the cache")));
    }
    std::fs::create_dir_all(cache).with_context(|| format!("creating {}", cache.display()))?;
    // Larger datasets merged from an older copy are stale now.
    for entry in std::fs::read_dir(cache).with_context(|| format!("reading {}", cache.display()))? {
        let path = entry?.path();
        let stale = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(&format!("{name}-x")) && n.ends_with(".complete.json"));
        if stale {
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        }
    }
    let t0 = Instant::now();
    generate(cache, &dir, spec)?;
    let seconds = t0.elapsed().as_secs_f64();
    mark(cache, &name, &how, seconds)?;
    Ok((dir, format!("{how}; generated in {seconds:.0} s")))
}

fn generate(cache: &Path, dir: &Path, spec: &DataSpec) -> Result<()> {
    let mut rig = Rig::load_or_builtin(RIG).with_context(|| format!("loading rig {RIG}"))?;
    let control_rate_hz = rig.control_rate_hz;
    for c in &mut rig.cameras {
        c.width = WIDTH;
        c.height = HEIGHT;
        // One frame per control tick: the converter keeps one per tick anyway.
        c.fps = control_rate_hz;
    }
    let tmp = cache.join("recordings.tmp");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("clearing {}", tmp.display()))?;
    }
    std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let jobs = spec.jobs.max(1);
    let opts = |overwrite: bool| JobOptions {
        convert: ConvertOptions {
            rig: Some(rig.clone()),
            width: WIDTH,
            height: HEIGHT,
            ..ConvertOptions::default()
        },
        overwrite,
        jobs,
        ..JobOptions::default()
    };
    let progress = bar(spec.episodes as u64, "episodes generated");
    progress.set_message(format!("into {}", dir.display()));
    let step = 2 * jobs;
    for first in (0..spec.episodes).step_by(step) {
        let ids: Vec<usize> = (first..(first + step).min(spec.episodes)).collect();
        let inputs = synthesize(&tmp, &rig, &ids, spec.seconds, TASK, jobs)?;
        let results = scaledp_converter::run(&inputs, dir, &opts(first == 0), &|_| {})
            .with_context(|| format!("converting into {}", dir.display()))?;
        for (path, outcome) in results {
            match outcome {
                Outcome::Converted(_) => {}
                Outcome::Skipped(why) => bail!("{}: skipped: {why}", path.display()),
                Outcome::Failed(line) => bail!("{line}"),
            }
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        }
        progress.inc(ids.len() as u64);
    }
    progress.finish_and_clear();
    std::fs::remove_dir_all(&tmp).ok();
    Ok(())
}

/// `factor` copies of `dataset` merged into one (made if absent or incomplete), and how.
pub(crate) fn ensure_larger(
    cache: &Path,
    dataset: &Path,
    spec: &DataSpec,
    factor: usize,
) -> Result<(PathBuf, String)> {
    let name = format!("{}-x{factor}", name(spec));
    let dir = cache.join(&name);
    let how = format!(
        "{} episodes: the dataset merged with itself {factor}× (scaledp dataset merge), each copy under its own episode indices and rows, so every episode is read and decoded from its own rows (contents repeat)",
        spec.episodes * factor
    );
    if complete(cache, &name, &how) {
        return Ok((dir, format!("{how}; reused from the cache")));
    }
    let progress = bar(0, "");
    progress.set_message(format!("merging {factor} copies into {}", dir.display()));
    progress.enable_steady_tick(std::time::Duration::from_millis(200));
    let t0 = Instant::now();
    let inputs = vec![dataset.to_path_buf(); factor];
    scaledp_converter::merge(&inputs, &dir, 100)
        .with_context(|| format!("merging into {}", dir.display()))?;
    progress.finish_and_clear();
    let seconds = t0.elapsed().as_secs_f64();
    mark(cache, &name, &how, seconds)?;
    Ok((dir, format!("{how}; merged in {seconds:.0} s")))
}

/// Names of the pure-decode threads (a prefix of at most 15 bytes, the kernel's `comm`).
const POOL_NAME: &str = "pure-decode-";

/// What the pure-decode run measured.
#[derive(Default)]
pub(crate) struct PureDecode {
    /// JPEGs decoded (by each pass).
    pub images: u64,
    /// zune-jpeg into a reused interleaved RGB buffer: the physical limit.
    pub zune: Pass,
    /// The loader's own decoder (`scaledp_datasets::decode_image`: zune-jpeg, then the
    /// channel-first layout) into a reused buffer: how much of the loader's cost is that step.
    pub chw: Pass,
}

/// Time spent in one pass over the JPEGs (parquet reading left out).
pub(crate) struct Pass {
    /// Wall seconds.
    pub seconds: f64,
    /// CPU seconds of the decoding threads (clock ticks from /proc); None if unreadable.
    pub cpu_s: Option<f64>,
}

impl Default for Pass {
    fn default() -> Self {
        Pass {
            seconds: 0.0,
            cpu_s: Some(0.0),
        }
    }
}

impl Pass {
    fn add(&mut self, wall: Duration, cpu_before: Option<f64>, cpu_after: Option<f64>) {
        self.seconds += wall.as_secs_f64();
        self.cpu_s = match (self.cpu_s, cpu_before, cpu_after) {
            (Some(c), Some(a), Some(b)) => Some(c + b - a),
            _ => None,
        };
    }
}

/// User + system CPU seconds of this process's pure-decode threads, from /proc (USER_HZ 100).
/// The threads do nothing but decode, so this is the decoding's CPU time.
fn pool_cpu_seconds() -> Option<f64> {
    let mut ticks = 0.0;
    let mut found = false;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let dir = task.ok()?.path();
        let comm = std::fs::read_to_string(dir.join("comm")).unwrap_or_default();
        if !comm.starts_with(POOL_NAME) {
            continue;
        }
        let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
        let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
        ticks += fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
        found = true;
    }
    found.then_some(ticks / 100.0)
}

thread_local! {
    static RGB: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    static CHW: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Decodes, for every sample of an epoch (every frame t of every episode), the JPEGs of frames
/// max(t−To+1, 0) ..= t of every camera — the images the loader decodes, same count — with
/// zune-jpeg into a reused per-thread buffer on a pool of `threads`, then again with the loader's
/// own decoder (to channel-first). Only the decoding is timed (the parquet reading is not).
pub(crate) fn pure_decode(dataset: &Path, to: usize, threads: usize) -> Result<PureDecode> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("{POOL_NAME}{i}"))
        .build()
        .context("starting the decode pool")?;
    let mut files = Vec::new();
    collect_parquet(&dataset.join("data"), &mut files)?;
    files.sort();
    let mut out = PureDecode::default();
    for path in &files {
        let file =
            std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
        let builder = ParquetRecordBatchReaderBuilder::try_new(file)
            .with_context(|| format!("reading {}", path.display()))?;
        let cams: Vec<String> = builder
            .schema()
            .fields()
            .iter()
            .map(|f| f.name().clone())
            .filter(|n| n.starts_with("observation.images."))
            .collect();
        // Episode by episode: (episode_index, per camera its JPEGs in frame order).
        let mut current: Option<(i64, Vec<Vec<Vec<u8>>>)> = None;
        let mut flush = |ep: Vec<Vec<Vec<u8>>>| -> Result<()> {
            let len = ep.first().map_or(0, Vec::len);
            let jobs: Vec<&[u8]> = (0..len)
                .flat_map(|t| (0..to).map(move |k| (t + k + 1).saturating_sub(to)))
                .flat_map(|f| ep.iter().map(move |cam| cam[f].as_slice()))
                .collect();
            let fail = |e: String| anyhow::anyhow!("{}: {e}", path.display());
            let (cpu0, t0) = (pool_cpu_seconds(), Instant::now());
            pool.install(|| jobs.par_iter().try_for_each(|j| decode_jpeg(j)))
                .map_err(fail)?;
            let (cpu1, t1) = (pool_cpu_seconds(), Instant::now());
            pool.install(|| jobs.par_iter().try_for_each(|j| decode_chw(j)))
                .map_err(fail)?;
            let cpu2 = pool_cpu_seconds();
            out.zune.add(t1 - t0, cpu0, cpu1);
            out.chw.add(t1.elapsed(), cpu1, cpu2);
            out.images += jobs.len() as u64;
            Ok(())
        };
        let reader = builder
            .with_batch_size(256)
            .build()
            .with_context(|| format!("reading {}", path.display()))?;
        for batch in reader {
            let batch = batch.with_context(|| format!("reading {}", path.display()))?;
            let episode: &Int64Array = batch
                .column_by_name("episode_index")
                .and_then(|c| c.as_primitive_opt())
                .with_context(|| format!("{}: no int64 episode_index", path.display()))?;
            let bytes: Vec<&arrow_array::BinaryArray> = cams
                .iter()
                .map(|c| {
                    batch
                        .column_by_name(c)
                        .and_then(|a| a.as_struct_opt())
                        .and_then(|s| s.column_by_name("bytes"))
                        .and_then(|b| b.as_binary_opt::<i32>())
                        .with_context(|| format!("{}: {c} is not an image struct", path.display()))
                })
                .collect::<Result<_>>()?;
            for row in 0..batch.num_rows() {
                let e = episode.value(row);
                if current.as_ref().is_some_and(|(ce, _)| *ce != e) {
                    if let Some((_, ep)) = current.take() {
                        flush(ep)?;
                    }
                }
                let (_, ep) = current.get_or_insert_with(|| (e, vec![Vec::new(); cams.len()]));
                for (c, b) in bytes.iter().enumerate() {
                    if b.is_null(row) {
                        bail!("{}: null image in {} row {row}", path.display(), cams[c]);
                    }
                    ep[c].push(b.value(row).to_vec());
                }
            }
        }
        if let Some((_, ep)) = current.take() {
            flush(ep)?;
        }
    }
    if out.images == 0 {
        bail!("{}: no images to decode", dataset.display());
    }
    Ok(out)
}

/// zune-jpeg → interleaved RGB in this thread's reused buffer.
fn decode_jpeg(jpeg: &[u8]) -> Result<(), String> {
    RGB.with(|buf| {
        let mut buf = buf.borrow_mut();
        let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
        let mut d = JpegDecoder::new_with_options(ZCursor::new(jpeg), options);
        d.decode_headers().map_err(|e| format!("JPEG: {e:?}"))?;
        let size = d.output_buffer_size().ok_or("JPEG too large")?;
        buf.resize(size, 0);
        d.decode_into(&mut buf).map_err(|e| format!("JPEG: {e:?}"))
    })
}

/// The loader's decoder → channel-first RGB in this thread's reused buffer.
fn decode_chw(jpeg: &[u8]) -> Result<(), String> {
    CHW.with(|buf| {
        let mut buf = buf.borrow_mut();
        buf.resize(3 * WIDTH as usize * HEIGHT as usize, 0);
        scaledp_datasets::decode_image(jpeg, WIDTH, HEIGHT, &mut buf)
    })
}

fn collect_parquet(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let path = entry?.path();
        if path.is_dir() {
            collect_parquet(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "parquet") {
            out.push(path);
        }
    }
    Ok(())
}
