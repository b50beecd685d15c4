//! The converter's floor on a machine: the work no conversion of MCAP recordings can skip,
//! done the converter's own way and nothing else. Every chunk of every recording is
//! decompressed (by the converter's reader: a large frame that ends a chunk stays compressed
//! unless it is kept, as in a conversion), and every `stride`-th frame of each camera (a 30 Hz
//! camera at 10 Hz output: 3) is decoded, resized and JPEG-encoded on the same pool as a
//! conversion's; no alignment, kinematics, hashing, Parquet or statistics. `scaledp bench
//! convert` prints a conversion's frames/s over this one's: how close the converter is to its
//! limit.

use std::path::PathBuf;
use std::time::Instant;

use rayon::prelude::*;

use crate::encode_pool::{encode_while, FrameJob};
use crate::error::{Error, Result};
use crate::frames::is_image;
use crate::images::EncodeSpec;
use crate::mcap_stream::stream;

/// What a floor pass did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorReport {
    /// Frames encoded (over all cameras).
    pub frames: u64,
    /// Bytes of the recordings.
    pub input_bytes: u64,
    /// Wall seconds.
    pub seconds: f64,
}

/// Runs the floor pass over the MCAP recordings `paths`, `jobs` at a time (see the module
/// docs); encodes every `stride`-th frame of each image topic per `spec`.
pub fn floor(
    paths: &[PathBuf],
    stride: usize,
    spec: &EncodeSpec,
    jobs: usize,
) -> Result<FloorReport> {
    let stride = stride.max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .map_err(|e| Error::input("floor", format!("thread pool: {e}")))?;
    let start = Instant::now();
    let counts: Vec<Result<(u64, u64)>> = pool.install(|| {
        paths
            .par_iter()
            .map(|path| {
                let bytes = std::fs::metadata(path).map_err(Error::io(path))?.len();
                let mut seen: std::collections::HashMap<String, usize> = Default::default();
                let (read, done) = encode_while(path, spec, |submit| {
                    stream(path, &mut |topic, log_time_ns, payload, _| {
                        if is_image(&topic.message_type) {
                            let k = seen.entry(topic.topic.clone()).or_default();
                            if *k % stride == 0 {
                                submit(FrameJob {
                                    key: (topic.topic.clone(), *k),
                                    message_type: topic.message_type.clone(),
                                    log_time_ns,
                                    bytes: payload.share(),
                                });
                            }
                            *k += 1;
                        }
                        Ok(true)
                    })
                    .map(drop)
                });
                read?;
                let mut frames = 0;
                for (_, r) in done {
                    r?;
                    frames += 1;
                }
                Ok((frames, bytes))
            })
            .collect()
    });
    let mut report = FloorReport {
        frames: 0,
        input_bytes: 0,
        seconds: 0.0,
    };
    for c in counts {
        let (frames, bytes) = c?;
        report.frames += frames;
        report.input_bytes += bytes;
    }
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}
