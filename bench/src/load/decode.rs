//! The pure-decode measurement of `bench load`: the JPEGs of an epoch's samples decoded with
//! nothing else around them, on a pool of the loader's size — the physical limit — and once
//! more with the loader's own decoder (which also lays pixels out channel-first).

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use arrow_array::cast::AsArray;
use arrow_array::{Array, BinaryArray, Int64Array, RecordBatch};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use rayon::prelude::*;
use scaledp_testkit::cpu_seconds_at;
use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;
use zune_jpeg::JpegDecoder;

use super::data::{HEIGHT, WIDTH};

/// Names of the pure-decode threads (a prefix of at most 15 bytes, the kernel's `comm`).
const POOL_NAME: &str = "pure-decode-";

/// One episode's JPEGs: per camera, in frame order.
type EpisodeJpegs = Vec<Vec<Vec<u8>>>;

/// What the pure-decode run measured.
#[derive(Default)]
pub struct PureDecode {
    /// JPEGs decoded (by each pass).
    pub images: u64,
    /// zune-jpeg into a reused interleaved RGB buffer: the physical limit.
    pub zune: Pass,
    /// The loader's own decoder (`scaledp_datasets::decode_image`: zune-jpeg, then the
    /// channel-first layout) into a reused buffer: how much of the loader's cost is that step.
    pub chw: Pass,
}

/// Time spent in one pass over the JPEGs (parquet reading left out).
pub struct Pass {
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

/// User + system CPU seconds of this process's pure-decode threads. The threads do nothing but
/// decode, so this is the decoding's CPU time.
fn pool_cpu_seconds() -> Option<f64> {
    let mut total = 0.0;
    let mut found = false;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let dir = task.ok()?.path();
        let comm = std::fs::read_to_string(dir.join("comm")).unwrap_or_default();
        if comm.starts_with(POOL_NAME) {
            total += cpu_seconds_at(&dir.join("stat"))?;
            found = true;
        }
    }
    found.then_some(total)
}

thread_local! {
    static RGB: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    static CHW: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Decodes, for every sample of an epoch (every frame t of every episode), the JPEGs of frames
/// max(t−To+1, 0) ..= t of every camera — the images the loader decodes, same count — with
/// zune-jpeg into a reused per-thread buffer on a pool of `threads`, then again with the loader's
/// own decoder (to channel-first). Only the decoding is timed (the parquet reading is not).
pub fn pure_decode(dataset: &Path, to: usize, threads: usize) -> Result<PureDecode> {
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
        for_each_episode(path, |ep| {
            out.decode_episode(&pool, &ep, to)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
        })?;
    }
    if out.images == 0 {
        bail!("{}: no images to decode", dataset.display());
    }
    Ok(out)
}

impl PureDecode {
    /// Both passes over the JPEGs of every sample of one episode.
    fn decode_episode(
        &mut self,
        pool: &rayon::ThreadPool,
        ep: &EpisodeJpegs,
        to: usize,
    ) -> Result<(), String> {
        let len = ep.first().map_or(0, Vec::len);
        let jobs: Vec<&[u8]> = (0..len)
            .flat_map(|t| (0..to).map(move |k| (t + k + 1).saturating_sub(to)))
            .flat_map(|f| ep.iter().map(move |cam| cam[f].as_slice()))
            .collect();
        let (cpu0, t0) = (pool_cpu_seconds(), Instant::now());
        pool.install(|| jobs.par_iter().try_for_each(|j| decode_jpeg(j)))?;
        let (cpu1, t1) = (pool_cpu_seconds(), Instant::now());
        pool.install(|| jobs.par_iter().try_for_each(|j| decode_chw(j)))?;
        let cpu2 = pool_cpu_seconds();
        self.zune.add(t1 - t0, cpu0, cpu1);
        self.chw.add(t1.elapsed(), cpu1, cpu2);
        self.images += jobs.len() as u64;
        Ok(())
    }
}

/// Reads a data file's image columns and hands `f` one episode's JPEGs at a time.
fn for_each_episode(path: &Path, mut f: impl FnMut(EpisodeJpegs) -> Result<()>) -> Result<()> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file)
        .with_context(|| format!("reading {}", path.display()))?;
    let cams: Vec<String> = builder
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .filter(|n| n.starts_with("observation.images."))
        .collect();
    let reader = builder
        .with_batch_size(256)
        .build()
        .with_context(|| format!("reading {}", path.display()))?;
    // (episode_index, its JPEGs so far)
    let mut current: Option<(i64, EpisodeJpegs)> = None;
    for batch in reader {
        let batch = batch.with_context(|| format!("reading {}", path.display()))?;
        let episode: &Int64Array = batch
            .column_by_name("episode_index")
            .and_then(|c| c.as_primitive_opt())
            .with_context(|| format!("{}: no int64 episode_index", path.display()))?;
        let bytes = image_columns(&batch, &cams, path)?;
        for row in 0..batch.num_rows() {
            let e = episode.value(row);
            if let Some((_, ep)) = current.take_if(|(ce, _)| *ce != e) {
                f(ep)?;
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
    match current {
        Some((_, ep)) => f(ep),
        None => Ok(()),
    }
}

/// The `bytes` field of each camera's image struct column.
fn image_columns<'a>(
    batch: &'a RecordBatch,
    cams: &[String],
    path: &Path,
) -> Result<Vec<&'a BinaryArray>> {
    cams.iter()
        .map(|c| {
            batch
                .column_by_name(c)
                .and_then(|a| a.as_struct_opt())
                .and_then(|s| s.column_by_name("bytes"))
                .and_then(|b| b.as_binary_opt::<i32>())
                .with_context(|| format!("{}: {c} is not an image struct", path.display()))
        })
        .collect()
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
        scaledp_datasets::decode_image(jpeg, WIDTH, HEIGHT, &mut buf).map_err(String::from)
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
