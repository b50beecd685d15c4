//! The bounded decoder cache: decoders are kept between samples with where they stand in their
//! track (the group they decode, the next sample to feed, the pictures already out), so a frame
//! later in the same group continues from there instead of starting again at the keyframe, and
//! decoders are not rebuilt for every frame. At most `capacity` are kept (least recently used
//! go first); a decoder is taken out while it works, so threads never share one.

use std::sync::Mutex;

use super::mp4::Track;
use scaledp_codec::Yuv420;
use scaledp_codec::{new_decoder, Decode};

/// Compressed samples of one track, consecutive in decode order, as read from the file.
pub(crate) struct Span<'a> {
    /// Identifies the track (its file) across spans.
    pub track_id: usize,
    pub track: &'a Track,
    /// Decode index of the first sample held.
    pub first: usize,
    /// The samples' bytes: sample `first + i` at `offsets[i]`.
    pub bytes: &'a [u8],
    pub offsets: &'a [(usize, usize)],
}

struct Slot {
    track_id: usize,
    dec: Box<dyn Decode>,
    /// The group being decoded (decode index of its keyframe).
    keyframe: usize,
    /// Next sample to feed.
    next: usize,
    /// Pictures of the group already handed out.
    shown: usize,
    /// A flush ended the decoder's stream: it must start again at a keyframe.
    flushed: bool,
}

/// Decoders kept between samples.
pub(crate) struct DecoderCache {
    slots: Mutex<Vec<Slot>>,
    capacity: usize,
}

impl DecoderCache {
    pub fn new(capacity: usize) -> Self {
        DecoderCache {
            slots: Mutex::new(Vec::new()),
            capacity: capacity.max(1),
        }
    }

    /// A kept decoder that can reach sample `target` of `span` by going on (same group, not
    /// past it yet, its next sample held in `span`), else any decoder of the track (to be
    /// reset), else none.
    fn take(&self, span: &Span<'_>, keyframe: usize, rank: usize) -> Option<Slot> {
        let mut slots = self.slots.lock().ok()?;
        let held = span.first..span.first + span.offsets.len() + 1;
        let fits = |s: &Slot| {
            s.track_id == span.track_id
                && !s.flushed
                && s.keyframe == keyframe
                && s.shown <= rank
                && held.contains(&s.next)
        };
        let at = slots
            .iter()
            .rposition(fits)
            .or_else(|| slots.iter().rposition(|s| s.track_id == span.track_id))?;
        Some(slots.remove(at))
    }

    fn put(&self, slot: Slot) {
        if let Ok(mut slots) = self.slots.lock() {
            if slots.len() >= self.capacity {
                slots.remove(0);
            }
            slots.push(slot);
        }
    }

    /// Decodes the picture of sample `target` (decode index, held in `span`) and hands it to
    /// `out`.
    pub fn picture(
        &self,
        span: &Span<'_>,
        target: usize,
        out: &mut dyn FnMut(Yuv420<'_>),
    ) -> Result<(), String> {
        let track = span.track;
        let s = track.samples[target];
        let (keyframe, rank) = (s.keyframe as usize, s.rank as usize);
        if keyframe < span.first {
            return Err(format!(
                "keyframe {keyframe} of sample {target} was not read (internal error)"
            ));
        }
        let fresh = |slot: Option<Slot>| -> Result<Slot, String> {
            // Same track, another place: start again at the keyframe, reusing the decoder.
            if let Some(mut slot) = slot {
                if slot.dec.reset() {
                    slot.keyframe = keyframe;
                    slot.next = keyframe;
                    slot.shown = 0;
                    slot.flushed = false;
                    return Ok(slot);
                }
            }
            Ok(Slot {
                track_id: span.track_id,
                dec: new_decoder(track.codec, &track.config)?,
                keyframe,
                next: keyframe,
                shown: 0,
                flushed: false,
            })
        };
        let mut slot = match self.take(span, keyframe, rank) {
            Some(slot)
                if slot.keyframe == keyframe
                    && !slot.flushed
                    && slot.shown <= rank
                    && slot.next >= span.first =>
            {
                slot
            }
            other => fresh(other)?,
        };
        let mut got = false;
        let result = decode_to(&mut slot, span, rank, &mut |p| {
            got = true;
            out(p);
        });
        match result {
            Ok(()) if got => {
                if !slot.flushed {
                    self.put(slot);
                } else if slot.dec.reset() {
                    // Kept to start again elsewhere: its position no longer fits any span.
                    slot.flushed = false;
                    slot.next = usize::MAX;
                    self.put(slot);
                }
                Ok(())
            }
            Ok(()) => Err(format!(
                "no picture for the frame at {:.4} s (sample {target})",
                s.pts_s
            )),
            // A decoder that failed is dropped, never reused.
            Err(e) => Err(e),
        }
    }
}

/// Feeds `slot` the span's samples until the picture of presentation rank `rank` of its group
/// comes out (flushing at the end of what the span holds), handing that picture to `out`.
fn decode_to(
    slot: &mut Slot,
    span: &Span<'_>,
    rank: usize,
    out: &mut dyn FnMut(Yuv420<'_>),
) -> Result<(), String> {
    let end = span.first + span.offsets.len();
    let group_end = span.track.samples[slot.keyframe..]
        .iter()
        .position(|s| s.keyframe as usize != slot.keyframe)
        .map_or(span.track.samples.len(), |n| slot.keyframe + n)
        .min(end);
    let mut done = false;
    while !done && slot.next < group_end {
        let (start, len) = span.offsets[slot.next - span.first];
        let sample = &span.bytes[start..start + len];
        slot.next += 1;
        let shown = &mut slot.shown;
        slot.dec.push(sample, &mut |p| {
            if *shown == rank {
                out(p);
                done = true;
            }
            *shown += 1;
        })?;
    }
    if !done {
        slot.flushed = true;
        let shown = &mut slot.shown;
        slot.dec.flush(&mut |p| {
            if *shown == rank {
                out(p);
            }
            *shown += 1;
        })?;
    }
    Ok(())
}
