//! A minimal MP4 (ISO BMFF) writer: one video track (`avc1` + `avcC` or `av01` + `av1C`) at a
//! constant frame rate, `moov` before `mdat` (faststart), no edit list, so that frame `k` is at
//! exactly `k / fps` seconds for ffmpeg (PyAV, torchcodec) and for `re_mp4`. Each piece
//! (episode) is one chunk; chunk offsets switch to `co64` past 4 GiB.

use crate::decode::Codec;
use crate::encoding::EncodedVideo;

/// Why an MP4 file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum Mp4Error {
    /// No pieces, or no samples in them.
    #[error("no video to write: no frames")]
    Empty,
    /// Pieces that cannot share one track.
    #[error("piece {index} differs from piece 0 in its {what}: one track needs equal codec, size and configuration")]
    Mismatch {
        /// The piece.
        index: usize,
        /// "codec", "size" or "configuration".
        what: &'static str,
    },
    /// A piece with a keyframe flag count unequal to its sample count.
    #[error("piece {index}: {samples} samples but {flags} keyframe flags")]
    Flags {
        /// The piece.
        index: usize,
        /// Its samples.
        samples: usize,
        /// Its flags.
        flags: usize,
    },
    /// A frame rate whose timescale (fps × 1000, rounded) is not a positive 32-bit number.
    #[error("{0} fps: the frame rate must be finite, at least 0.001 and below 4 million")]
    Fps(f64),
    /// Something MP4's fields cannot hold.
    #[error("too large for MP4: {0}")]
    TooLarge(String),
}

/// Media time units per sample: timescale = round(fps × 1000), so 30 fps is 30000/1000 and
/// 29.97 fps 29970/1000 exactly.
const SAMPLE_DURATION: u32 = 1000;
/// The movie header's timescale (milliseconds).
const MOVIE_TIMESCALE: u32 = 1000;
const MATRIX: [u32; 9] = [0x10000, 0, 0, 0, 0x10000, 0, 0, 0, 0x4000_0000];

/// One video track at a constant frame rate, from one or more encoded pieces (episodes) whose
/// codec, size and config are equal; the samples are concatenated in order, sample `k` at
/// `k / fps` seconds.
pub fn mp4_file(pieces: &[&EncodedVideo], fps: f64) -> Result<Vec<u8>, Mp4Error> {
    let first = pieces.first().ok_or(Mp4Error::Empty)?;
    for (index, p) in pieces.iter().enumerate() {
        let what = if p.codec != first.codec {
            "codec"
        } else if (p.width, p.height) != (first.width, first.height) {
            "size"
        } else if p.config != first.config {
            "configuration"
        } else if p.keyframes.len() != p.samples.len() {
            return Err(Mp4Error::Flags {
                index,
                samples: p.samples.len(),
                flags: p.keyframes.len(),
            });
        } else {
            continue;
        };
        return Err(Mp4Error::Mismatch { index, what });
    }
    let timescale = fps * f64::from(SAMPLE_DURATION);
    if !(timescale.is_finite() && timescale >= 1.0 && timescale < f64::from(u32::MAX)) {
        return Err(Mp4Error::Fps(fps));
    }
    let timescale = timescale.round() as u32;
    let (w, h) = (first.width, first.height);
    if w > 0xFFFF || h > 0xFFFF {
        return Err(Mp4Error::TooLarge(format!("a {w}×{h} picture")));
    }
    // One chunk per piece that has samples.
    let chunks: Vec<&EncodedVideo> = pieces
        .iter()
        .copied()
        .filter(|p| !p.samples.is_empty())
        .collect();
    let sizes = chunks
        .iter()
        .flat_map(|p| p.samples.iter())
        .map(|s| u32::try_from(s.len()))
        .collect::<Result<Vec<u32>, _>>()
        .map_err(|_| Mp4Error::TooLarge("a sample over 4 GiB".into()))?;
    if sizes.is_empty() {
        return Err(Mp4Error::Empty);
    }
    u32::try_from(sizes.len())
        .map_err(|_| Mp4Error::TooLarge(format!("{} samples", sizes.len())))?;
    let chunk_bytes: Vec<u64> = chunks
        .iter()
        .map(|p| p.samples.iter().map(|s| s.len() as u64).sum())
        .collect();
    let payload: u64 = chunk_bytes.iter().sum();
    let sync: Vec<u32> = (1..)
        .zip(chunks.iter().flat_map(|p| p.keyframes.iter()))
        .filter_map(|(n, &k)| k.then_some(n))
        .collect();
    let track = Track {
        codec: first.codec,
        config: &first.config,
        width: w as u16,
        height: h as u16,
        timescale,
        sizes: &sizes,
        sync: &sync,
        chunk_samples: chunks.iter().map(|p| p.samples.len() as u32).collect(),
    };

    let ftyp = ftyp(first.codec);
    let mdat_header = if payload + 8 > u64::from(u32::MAX) {
        16
    } else {
        8
    };
    // The moov's size depends on the offsets' width only (4 bytes each, 8 in `co64`).
    let offsets_from = |moov_len: usize| {
        let mut at = (ftyp.len() + moov_len) as u64 + mdat_header;
        chunk_bytes
            .iter()
            .map(|n| {
                at += n;
                at - n
            })
            .collect::<Vec<u64>>()
    };
    let narrow = track.moov(&vec![0; chunks.len()], false).len();
    let mut offsets = offsets_from(narrow);
    let wide = offsets.last().is_some_and(|&o| o > u64::from(u32::MAX));
    if wide {
        offsets = offsets_from(narrow + 4 * chunks.len());
    }
    let moov = track.moov(&offsets, wide);

    let total = ftyp.len() + moov.len() + mdat_header as usize + payload as usize;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&ftyp);
    out.extend_from_slice(&moov);
    if mdat_header == 16 {
        out.extend_from_slice(&1u32.to_be_bytes());
        out.extend_from_slice(b"mdat");
        out.extend_from_slice(&(payload + 16).to_be_bytes());
    } else {
        out.extend_from_slice(&(payload as u32 + 8).to_be_bytes());
        out.extend_from_slice(b"mdat");
    }
    for s in chunks.iter().flat_map(|p| p.samples.iter()) {
        out.extend_from_slice(s);
    }
    debug_assert_eq!(out.len(), total);
    Ok(out)
}

fn ftyp(codec: Codec) -> Vec<u8> {
    let mut b = Vec::new();
    boxed(&mut b, b"ftyp", |b| {
        b.extend_from_slice(b"isom");
        put32(b, 512);
        b.extend_from_slice(b"isomiso2mp41");
        b.extend_from_slice(sample_entry_name(codec));
    });
    b
}

fn sample_entry_name(codec: Codec) -> &'static [u8; 4] {
    match codec {
        Codec::H264 => b"avc1",
        Codec::Av1 => b"av01",
    }
}

struct Track<'a> {
    codec: Codec,
    config: &'a [u8],
    width: u16,
    height: u16,
    timescale: u32,
    sizes: &'a [u32],
    /// Sync sample numbers (from 1).
    sync: &'a [u32],
    chunk_samples: Vec<u32>,
}

impl Track<'_> {
    fn moov(&self, chunk_offsets: &[u64], co64: bool) -> Vec<u8> {
        let media_duration = self.sizes.len() as u64 * u64::from(SAMPLE_DURATION);
        // In the movie's milliseconds, rounded.
        let ms = (u128::from(media_duration) * u128::from(MOVIE_TIMESCALE)
            + u128::from(self.timescale / 2))
            / u128::from(self.timescale);
        let movie_duration = u64::try_from(ms).unwrap_or(u64::MAX);
        let mut b = Vec::new();
        boxed(&mut b, b"moov", |b| {
            let v1 = movie_duration > u64::from(u32::MAX);
            full(b, b"mvhd", u8::from(v1), 0, |b| {
                times(b, v1, MOVIE_TIMESCALE, movie_duration);
                put32(b, 0x10000); // rate 1.0
                b.extend_from_slice(&[1, 0]); // volume 1.0
                b.extend_from_slice(&[0; 10]);
                MATRIX.iter().for_each(|&m| put32(b, m));
                b.extend_from_slice(&[0; 24]);
                put32(b, 2); // next track ID
            });
            boxed(b, b"trak", |b| {
                full(b, b"tkhd", u8::from(v1), 3, |b| {
                    // enabled | in movie
                    if v1 {
                        b.extend_from_slice(&[0; 16]);
                    } else {
                        b.extend_from_slice(&[0; 8]);
                    }
                    put32(b, 1); // track ID
                    put32(b, 0);
                    put_time(b, v1, movie_duration);
                    b.extend_from_slice(&[0; 16]); // reserved, layer, group, volume, reserved
                    MATRIX.iter().for_each(|&m| put32(b, m));
                    put32(b, u32::from(self.width) << 16);
                    put32(b, u32::from(self.height) << 16);
                });
                boxed(b, b"mdia", |b| {
                    self.mdia(b, media_duration, chunk_offsets, co64)
                });
            });
        });
        b
    }

    fn mdia(&self, b: &mut Vec<u8>, duration: u64, chunk_offsets: &[u64], co64: bool) {
        let v1 = duration > u64::from(u32::MAX);
        full(b, b"mdhd", u8::from(v1), 0, |b| {
            times(b, v1, self.timescale, duration);
            b.extend_from_slice(&[0x55, 0xC4, 0, 0]); // language "und", pre_defined
        });
        full(b, b"hdlr", 0, 0, |b| {
            put32(b, 0);
            b.extend_from_slice(b"vide");
            b.extend_from_slice(&[0; 12]);
            b.extend_from_slice(b"VideoHandler\0");
        });
        boxed(b, b"minf", |b| {
            full(b, b"vmhd", 0, 1, |b| b.extend_from_slice(&[0; 8]));
            boxed(b, b"dinf", |b| {
                full(b, b"dref", 0, 0, |b| {
                    put32(b, 1);
                    full(b, b"url ", 0, 1, |_| {}); // media in this file
                });
            });
            boxed(b, b"stbl", |b| self.stbl(b, chunk_offsets, co64));
        });
    }

    fn stbl(&self, b: &mut Vec<u8>, chunk_offsets: &[u64], co64: bool) {
        full(b, b"stsd", 0, 0, |b| {
            put32(b, 1);
            boxed(b, sample_entry_name(self.codec), |b| {
                b.extend_from_slice(&[0; 6]);
                b.extend_from_slice(&[0, 1]); // data reference index
                b.extend_from_slice(&[0; 16]); // pre_defined, reserved
                b.extend_from_slice(&self.width.to_be_bytes());
                b.extend_from_slice(&self.height.to_be_bytes());
                put32(b, 0x0048_0000); // 72 dpi
                put32(b, 0x0048_0000);
                put32(b, 0);
                b.extend_from_slice(&[0, 1]); // frame count
                b.extend_from_slice(&[0; 32]); // compressor name
                b.extend_from_slice(&[0, 0x18, 0xFF, 0xFF]); // depth, pre_defined -1
                let kind = match self.codec {
                    Codec::H264 => b"avcC",
                    Codec::Av1 => b"av1C",
                };
                boxed(b, kind, |b| b.extend_from_slice(self.config));
            });
        });
        full(b, b"stts", 0, 0, |b| {
            put32(b, 1);
            put32(b, self.sizes.len() as u32);
            put32(b, SAMPLE_DURATION);
        });
        if self.sync.len() != self.sizes.len() {
            full(b, b"stss", 0, 0, |b| {
                put32(b, self.sync.len() as u32);
                self.sync.iter().for_each(|&n| put32(b, n));
            });
        }
        full(b, b"stsc", 0, 0, |b| {
            // A run per change of samples per chunk: (first chunk, samples per chunk, entry 1).
            let runs: Vec<(u32, u32)> = (1..)
                .zip(self.chunk_samples.iter().copied())
                .filter(|&(i, n)| i == 1 || self.chunk_samples[i as usize - 2] != n)
                .collect();
            put32(b, runs.len() as u32);
            for (first, n) in runs {
                [first, n, 1].iter().for_each(|&v| put32(b, v));
            }
        });
        full(b, b"stsz", 0, 0, |b| {
            put32(b, 0);
            put32(b, self.sizes.len() as u32);
            self.sizes.iter().for_each(|&s| put32(b, s));
        });
        let kind = if co64 { b"co64" } else { b"stco" };
        full(b, kind, 0, 0, |b| {
            put32(b, chunk_offsets.len() as u32);
            for &o in chunk_offsets {
                if co64 {
                    b.extend_from_slice(&o.to_be_bytes());
                } else {
                    put32(b, o as u32);
                }
            }
        });
    }
}

fn put32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_be_bytes());
}

fn put_time(b: &mut Vec<u8>, v1: bool, t: u64) {
    if v1 {
        b.extend_from_slice(&t.to_be_bytes());
    } else {
        put32(b, t as u32);
    }
}

/// Creation and modification time (0), timescale, duration.
fn times(b: &mut Vec<u8>, v1: bool, timescale: u32, duration: u64) {
    b.extend_from_slice(if v1 { &[0; 16] } else { &[0; 8] });
    put32(b, timescale);
    put_time(b, v1, duration);
}

/// A box: size, type, then what `body` writes.
fn boxed(b: &mut Vec<u8>, kind: &[u8; 4], body: impl FnOnce(&mut Vec<u8>)) {
    let start = b.len();
    b.extend_from_slice(&[0; 4]);
    b.extend_from_slice(kind);
    body(b);
    let size = (b.len() - start) as u32;
    b[start..start + 4].copy_from_slice(&size.to_be_bytes());
}

/// A full box: a box whose body starts with its version and 24 bits of flags.
fn full(b: &mut Vec<u8>, kind: &[u8; 4], version: u8, flags: u32, body: impl FnOnce(&mut Vec<u8>)) {
    boxed(b, kind, |b| {
        put32(b, u32::from(version) << 24 | flags);
        body(b);
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A piece of `n` fake samples (sample `i` is `i + 1` bytes of `tag`), keyframes every 2nd.
    fn piece(n: usize, tag: u8) -> EncodedVideo {
        EncodedVideo {
            codec: Codec::H264,
            width: 64,
            height: 48,
            config: vec![1, 66, 0, 30, 0xFF, 0xE0, 0],
            samples: (0..n).map(|i| vec![tag; i + 1]).collect(),
            keyframes: (0..n).map(|i| i % 2 == 0).collect(),
        }
    }

    #[test]
    fn chunks_of_unequal_pieces_and_sync_samples_read_back() {
        let (a, b, c, empty) = (piece(3, 1), piece(3, 2), piece(2, 3), piece(0, 9));
        let file = mp4_file(&[&a, &empty, &b, &c], 29.97).unwrap();
        let mp4 = re_mp4::Mp4::read_bytes(&file).unwrap();
        let track = mp4.tracks().values().next().unwrap();
        assert_eq!(track.timescale, 29_970);
        assert_eq!(track.samples.len(), 8);
        let want = a.samples.iter().chain(&b.samples).chain(&c.samples);
        for (k, (s, w)) in track.samples.iter().zip(want).enumerate() {
            assert_eq!(&file[s.offset as usize..][..s.size as usize], w.as_slice());
            assert_eq!(s.composition_timestamp, k as i64 * 1000);
            assert_eq!(s.is_sync, [0, 2, 3, 5, 6].contains(&k), "sample {k}");
        }
        let stbl = &track.trak(&mp4).mdia.minf.stbl;
        assert_eq!(
            stbl.stsc.entries.len(),
            2,
            "3 and 3, then 2 samples a chunk"
        );
        assert_eq!(stbl.stco.as_ref().map(|c| c.entries.len()), Some(3));
        // All keyframes: no stss, every sample sync.
        let mut all = piece(4, 1);
        all.keyframes = vec![true; 4];
        let file = mp4_file(&[&all], 30.0).unwrap();
        assert!(!file.windows(4).any(|w| w == b"stss"));
        let mp4 = re_mp4::Mp4::read_bytes(&file).unwrap();
        let track = mp4.tracks().values().next().unwrap();
        assert!(track.samples.iter().all(|s| s.is_sync));
    }

    #[test]
    fn offsets_past_4_gib_are_written_in_co64() {
        let sync = [1];
        let track = Track {
            codec: Codec::Av1,
            config: &[0x81, 0, 0x0C, 0],
            width: 2,
            height: 2,
            timescale: 30_000,
            sizes: &[1, 1],
            sync: &sync,
            chunk_samples: vec![1, 1],
        };
        let narrow = track.moov(&[100, 101], false);
        let wide = track.moov(&[100, 1 << 32], true);
        assert_eq!(wide.len(), narrow.len() + 8);
        let at = wide.windows(4).position(|w| w == b"co64").unwrap();
        assert_eq!(wide[at + 12..at + 20], 100u64.to_be_bytes());
        assert_eq!(wide[at + 20..at + 28], (1u64 << 32).to_be_bytes());
    }

    #[test]
    fn bad_frame_rates_and_flags_are_refused() {
        let a = piece(2, 1);
        for fps in [0.0, -30.0, f64::NAN, f64::INFINITY, 1e-4, 5e6] {
            let err = mp4_file(&[&a], fps).unwrap_err();
            assert!(matches!(err, Mp4Error::Fps(_)), "{fps}: {err}");
        }
        let mut b = piece(2, 1);
        b.keyframes.pop();
        let err = mp4_file(&[&a, &b], 30.0).unwrap_err();
        assert_eq!(err.to_string(), "piece 1: 2 samples but 1 keyframe flags");
        let empty = piece(0, 1);
        let err = mp4_file(&[&empty], 30.0).unwrap_err();
        assert_eq!(err.to_string(), "no video to write: no frames");
    }
}
