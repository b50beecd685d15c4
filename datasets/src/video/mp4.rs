//! The index of one MP4 video file, read from its `moov` box only (`re_mp4`, the demuxer rerun
//! uses; `mdat` is skipped by seeking, so opening a 200 MB file reads a few hundred KB): the
//! first video track's codec and configuration, and every sample's place in the file, its
//! presentation time and whether it is a keyframe. Samples are kept in decode order; for each,
//! its group of pictures (the keyframe it is decoded from) and its presentation rank there.

use std::io::{Read, Seek};

use scaledp_codec::Codec;

/// One sample (an access unit) of the track.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleRef {
    pub offset: u64,
    pub size: u32,
    /// Presentation time in seconds (the first frame at 0, as ffmpeg reports it).
    pub pts_s: f64,
    /// Decode index of the keyframe this sample is decoded from.
    pub keyframe: u32,
    /// Pictures of the group (from `keyframe` on) shown before this one.
    pub rank: u32,
}

/// A video track's index.
#[derive(Debug)]
pub(crate) struct Track {
    pub codec: Codec,
    /// The sample entry's configuration record (`avcC`, `av1C`).
    pub config: Vec<u8>,
    /// Samples in decode order.
    pub samples: Vec<SampleRef>,
    /// Decode indices sorted by presentation time.
    pub by_pts: Vec<u32>,
}

/// Most samples of one track (a day at 60 fps): a larger count is a corrupt header.
const MAX_SAMPLES: usize = 6_000_000;

impl Track {
    /// Reads the index of the first video track from `reader` (`size` bytes).
    pub fn read<R: Read + Seek>(mut reader: R, size: u64) -> Result<Track, String> {
        let size = readable_end(&mut reader, size)?;
        reader.rewind().map_err(|e| e.to_string())?;
        let mp4 = re_mp4::Mp4::read(reader, size).map_err(|e| {
            let e = e.to_string();
            if e.contains("larger size")
                || e.contains("failed to fill")
                || e.contains("end of file")
            {
                format!("MP4 cut short or corrupt ({e})")
            } else {
                format!("not a readable MP4: {e}")
            }
        })?;
        let track = mp4
            .tracks()
            .values()
            .find(|t| t.kind == Some(re_mp4::TrackKind::Video))
            .ok_or("MP4 without a video track")?;
        let stsd = &track.trak(&mp4).mdia.minf.stbl.stsd.contents;
        let codec = match stsd {
            re_mp4::StsdBoxContent::Av01(_) => Codec::Av1,
            re_mp4::StsdBoxContent::Avc1(_) => Codec::H264,
            other => {
                let name = other.codec_string().unwrap_or_else(|| "unknown".into());
                return Err(format!(
                    "video codec {name}: not decoded here (AV1 and H.264 are; re-encode with `scaledp convert --video av1`)"
                ));
            }
        };
        let config = track.raw_codec_config(&mp4).unwrap_or_default();
        if track.samples.is_empty() || track.samples.len() > MAX_SAMPLES {
            return Err(format!("video track with {} samples", track.samples.len()));
        }
        if track.timescale == 0 {
            return Err("video track with a timescale of 0".into());
        }
        let samples = index(&track.samples, track.timescale)?;
        let mut by_pts: Vec<u32> = (0..samples.len() as u32).collect();
        by_pts.sort_by(|&a, &b| {
            samples[a as usize]
                .pts_s
                .total_cmp(&samples[b as usize].pts_s)
        });
        Ok(Track {
            codec,
            config,
            samples,
            by_pts,
        })
    }

    /// The last sample (decode index) to feed before sample `d`'s picture can come out: the
    /// latest in decode order of its group's samples shown no later than it.
    pub fn last_needed(&self, d: usize) -> usize {
        let s = self.samples[d];
        let k = s.keyframe as usize;
        self.samples[k..]
            .iter()
            .take_while(|x| x.keyframe == s.keyframe)
            .enumerate()
            .filter(|(_, x)| x.rank <= s.rank)
            .map(|(i, _)| k + i)
            .max()
            .unwrap_or(d)
    }

    /// The decode index of the sample shown nearest to `t_s`, and how far from it it is.
    pub fn nearest(&self, t_s: f64) -> (u32, f64) {
        let pts = |i: usize| self.samples[self.by_pts[i] as usize].pts_s;
        let i = self
            .by_pts
            .partition_point(|&d| self.samples[d as usize].pts_s < t_s);
        let best = [i.saturating_sub(1), i.min(self.by_pts.len() - 1)]
            .into_iter()
            .min_by(|&a, &b| (pts(a) - t_s).abs().total_cmp(&(pts(b) - t_s).abs()))
            .unwrap_or(0);
        (self.by_pts[best], (pts(best) - t_s).abs())
    }
}

/// Where the boxes worth parsing end: the file's size, or — when a box runs past the end of a
/// file cut short, after the index (`moov`) was complete — the end of the last whole box, so
/// the frames before the cut still load and those after it fail one by one. A cut before the
/// index is an error.
fn readable_end<R: Read + Seek>(r: &mut R, size: u64) -> Result<u64, String> {
    let (mut at, mut moov) = (0u64, false);
    while at + 8 <= size {
        let mut h = [0u8; 16];
        r.seek(std::io::SeekFrom::Start(at))
            .and_then(|_| r.read_exact(&mut h[..8]))
            .map_err(|e| format!("MP4 box header at {at}: {e}"))?;
        let small = u64::from(u32::from_be_bytes([h[0], h[1], h[2], h[3]]));
        let kind = String::from_utf8_lossy(&h[4..8]).into_owned();
        let len = match small {
            0 => size - at,
            1 => {
                r.read_exact(&mut h[8..16])
                    .map_err(|e| format!("MP4 box header at {at}: {e}"))?;
                u64::from_be_bytes([h[8], h[9], h[10], h[11], h[12], h[13], h[14], h[15]])
            }
            n => n,
        };
        if len < 8 {
            return Err(format!(
                "not a readable MP4: {kind} box of {len} bytes at {at}"
            ));
        }
        if at.saturating_add(len) > size {
            if moov {
                return Ok(at);
            }
            return Err(format!(
                "MP4 cut short: its {kind} box at {at} needs {len} bytes, the file has {size}"
            ));
        }
        moov |= kind == "moov";
        at += len;
    }
    Ok(size)
}

/// Decode-order samples with their groups: a group starts at a keyframe (sync sample) and
/// holds the samples up to the next one; the first sample must be a keyframe.
fn index(samples: &[re_mp4::Sample], timescale: u64) -> Result<Vec<SampleRef>, String> {
    if !samples[0].is_sync {
        return Err("video track does not start with a keyframe".into());
    }
    let mut out: Vec<SampleRef> = Vec::with_capacity(samples.len());
    let mut group_start = 0usize;
    let finish = |out: &mut Vec<SampleRef>, start: usize| {
        let group = &mut out[start..];
        let mut order: Vec<usize> = (0..group.len()).collect();
        order.sort_by(|&a, &b| group[a].pts_s.total_cmp(&group[b].pts_s));
        for (rank, i) in order.into_iter().enumerate() {
            group[i].rank = rank as u32;
        }
    };
    for (i, s) in samples.iter().enumerate() {
        if s.is_sync && i > 0 {
            finish(&mut out, group_start);
            group_start = i;
        }
        let size = u32::try_from(s.size).map_err(|_| format!("sample {i} of {} bytes", s.size))?;
        out.push(SampleRef {
            offset: s.offset,
            size,
            pts_s: s.composition_timestamp as f64 / timescale as f64,
            keyframe: group_start as u32,
            rank: 0,
        });
    }
    finish(&mut out, group_start);
    Ok(out)
}
