//! Camera frames encoded on the rayon pool while the thread that reads the recording goes on.
//! The reader never blocks: when more than a few frames wait, it encodes one itself, so memory
//! stays bounded (each waiting frame holds its decompressed chunk) and a pool whose every thread
//! is a reader cannot deadlock.

use std::collections::{HashMap, VecDeque};
use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use crate::error::Error;
use crate::error::Result;
use crate::images::{encode_message, EncodeSpec, EncodedFrame};
use crate::mcap_stream::FrameBytes;
use crate::source::Serialization;

/// A camera frame: (topic, stored ordinal).
pub type FrameKey = (String, usize);

/// One CDR camera message to encode.
#[derive(Debug)]
pub struct FrameJob {
    /// (topic, stored ordinal).
    pub key: FrameKey,
    /// Its type, `sensor_msgs/msg/Image` or `…/CompressedImage`.
    pub message_type: String,
    /// Its log time (ns), for error messages.
    pub log_time_ns: u64,
    /// The serialized message.
    pub bytes: FrameBytes,
}

/// Each frame's encoding, or why it failed (reported only if the frame turns out to be used).
pub type Encodings = HashMap<FrameKey, Result<EncodedFrame>>;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Runs `read`, which hands frames to encode to the function it is given; returns what `read`
/// returned and every frame's encoding once all are done.
pub fn encode_while<R: Send>(
    path: &Path,
    spec: &EncodeSpec,
    read: impl FnOnce(&mut dyn FnMut(FrameJob)) -> Result<R> + Send,
) -> (Result<R>, Encodings) {
    let queue: Mutex<VecDeque<FrameJob>> = Mutex::new(VecDeque::new());
    let done: Mutex<Encodings> = Mutex::new(HashMap::new());
    let run_one = || {
        let job = lock(&queue).pop_front();
        if let Some(job) = job {
            let r = job
                .bytes
                .with(|data| {
                    encode_message(
                        path,
                        &job.key.0,
                        &job.message_type,
                        job.log_time_ns,
                        Serialization::Cdr,
                        data,
                        spec,
                    )
                })
                .unwrap_or_else(|e| Err(Error::input(path, format!("corrupt MCAP chunk: {e}"))));
            drop(job.bytes);
            lock(&done).insert(job.key, r);
        }
    };
    // Frames waiting beyond this are encoded by the reader itself.
    let max_waiting = rayon::current_num_threads().max(2);
    let result = rayon::scope(|s| {
        let mut submit = |job: FrameJob| {
            lock(&queue).push_back(job);
            s.spawn(|_| run_one());
            while lock(&queue).len() > max_waiting {
                run_one();
            }
        };
        read(&mut submit)
    });
    (result, done.into_inner().unwrap_or_else(|p| p.into_inner()))
}
