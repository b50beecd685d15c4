//! LZ4 frame decoding (<https://github.com/lz4/lz4/blob/dev/doc/lz4_Frame_format.md>) straight
//! into a caller's buffer, block by block with `lz4_flex`, without verifying the frame's XXH32
//! checksums: they cost more CPU than the decompression itself (camera chunks of 11 MB compress
//! ~20×, and their decoding runs at memory speed). An MCAP chunk carries its own CRC-32 of the
//! uncompressed records, which [`crate::mcap_stream`] checks instead (when the chunk header
//! records one, i.e. it is non-zero): over the whole chunk before any of its messages is handed
//! out, except for a chunk whose large last message is left compressed ([`Tail`]). There the CRC
//! is finished each time that message is decoded, and a mismatch fails the decode; its
//! messages before it are handed out unverified, and if the last message is never decoded (a
//! frame the conversion does not pick), that chunk's CRC is never checked.

const FRAME_MAGIC: u32 = 0x184D_2204;
/// Skippable frames: magic 0x184D2A50..=0x184D2A5F, then a 4-byte length.
const SKIPPABLE_MAGIC: u32 = 0x184D_2A50;
/// Linked blocks may reference this much of the output before them.
const WINDOW: usize = 64 << 10;

fn u32_at(src: &[u8], at: usize) -> Result<u32, String> {
    src.get(at..at + 4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .ok_or_else(|| format!("lz4: truncated at byte {at}"))
}

/// Decodes every frame in `src` (skippable frames skipped) into `dst`, stopping once `dst` is
/// full; returns the bytes written. Fails on a malformed frame and on dictionary frames.
#[cfg(test)]
pub fn decompress_frames(src: &[u8], dst: &mut [u8]) -> Result<usize, String> {
    Decoder::default().decode(src, dst, 0, dst.len())
}

/// The frame being decoded.
#[derive(Debug, Clone, Copy)]
struct Frame {
    independent: bool,
    block_checksums: bool,
    content_checksum: bool,
    /// Output position where the frame's data starts (linked blocks look back no further).
    start: usize,
}

/// Where decoding of a sequence of frames stands: it can stop at a block boundary and go on
/// later, possibly from a copy of the input left and of the output's last 64 KiB.
#[derive(Debug, Clone, Default)]
pub struct Decoder {
    /// Input position.
    at: usize,
    frame: Option<Frame>,
}

impl Decoder {
    /// Decodes `src` from where this decoder stands into `dst` from output position `pos`
    /// (`dst[..pos]` holding the output so far), whole blocks at a time, until at least `until`
    /// bytes are out or `src` ends; returns the new output position.
    pub fn decode(
        &mut self,
        src: &[u8],
        dst: &mut [u8],
        mut pos: usize,
        until: usize,
    ) -> Result<usize, String> {
        while pos < until {
            let Some(f) = self.frame else {
                if self.at >= src.len() {
                    break;
                }
                self.frame_header(src, pos)?;
                continue;
            };
            let at = self.at;
            let size = u32_at(src, at)?;
            if size == 0 {
                self.at = at + 4 + if f.content_checksum { 4 } else { 0 };
                if self.at > src.len() {
                    return Err("lz4: truncated after the last block".into());
                }
                self.frame = None;
                continue;
            }
            let len = (size & 0x7FFF_FFFF) as usize;
            let block = src.get(at + 4..at + 4 + len).ok_or_else(|| {
                format!("lz4: block of {len} bytes at byte {at} runs past the end")
            })?;
            self.at = at + 4 + len + if f.block_checksums { 4 } else { 0 };
            let bad = |e: lz4_flex::block::DecompressError| format!("lz4 block at byte {at}: {e}");
            pos += if size & 0x8000_0000 != 0 {
                dst.get_mut(pos..pos + len)
                    .ok_or("lz4: output larger than expected")?
                    .copy_from_slice(block);
                len
            } else if f.independent || pos <= f.start {
                lz4_flex::block::decompress_into(block, &mut dst[pos..]).map_err(bad)?
            } else {
                let (before, rest) = dst.split_at_mut(pos);
                let dict = &before[pos.saturating_sub(WINDOW).max(f.start)..];
                lz4_flex::block::decompress_into_with_dict(block, rest, dict).map_err(bad)?
            };
        }
        Ok(pos)
    }

    /// Reads a frame header (or skips a skippable frame) at the input position.
    fn frame_header(&mut self, src: &[u8], pos: usize) -> Result<(), String> {
        let at = self.at;
        let magic = u32_at(src, at)?;
        if magic & 0xFFFF_FFF0 == SKIPPABLE_MAGIC {
            self.at = at + 8 + u32_at(src, at + 4)? as usize;
            return Ok(());
        }
        if magic != FRAME_MAGIC {
            return Err(format!("lz4: bad frame magic {magic:#010x} at byte {at}"));
        }
        let flg = *src
            .get(at + 4)
            .ok_or_else(|| format!("lz4: truncated frame descriptor at byte {at}"))?;
        if flg >> 6 != 1 {
            return Err(format!("lz4: unsupported frame version {}", flg >> 6));
        }
        if flg & 0x01 != 0 {
            return Err("lz4: dictionary frames are not supported".into());
        }
        let content_size = flg & 0x08 != 0;
        // Magic, FLG, BD, optional content size, header checksum.
        self.at = at + 7 + if content_size { 8 } else { 0 };
        self.frame = Some(Frame {
            independent: flg & 0x20 != 0,
            block_checksums: flg & 0x10 != 0,
            content_checksum: flg & 0x04 != 0,
            start: pos,
        });
        Ok(())
    }

    /// Splits off the rest of the work: the input not decoded yet and a decoder for it whose
    /// output positions are shifted down by `base` (the output from `base` on is carried over).
    fn rebase(&self, src: &[u8], base: usize) -> (Decoder, Vec<u8>) {
        let frame = self.frame.map(|f| Frame {
            start: f.start.saturating_sub(base),
            ..f
        });
        let rest = src.get(self.at..).unwrap_or_default().to_vec();
        (Decoder { at: 0, frame }, rest)
    }
}

/// The end of an LZ4 chunk left undecoded: one large record whose bytes may never be needed.
/// Holds a copy of the compressed input left, of the output's last 64 KiB and of the record's
/// bytes decoded so far, so it can be finished later, on any thread.
#[derive(Debug)]
pub struct Tail {
    /// Output from `base` (window and the part of the record already decoded).
    head: Vec<u8>,
    rest: Vec<u8>,
    decoder: Decoder,
    /// The record's bytes, relative to `base`.
    range: std::ops::Range<usize>,
    /// The CRC-32 state over the chunk's bytes before `base + head.len()`, and the CRC the
    /// whole chunk must have.
    crc: Option<(crc32fast::Hasher, u32)>,
}

/// The reason for a chunk whose records have CRC-32 `computed` where its header says `recorded`.
pub fn crc_mismatch(computed: u32, recorded: u32) -> String {
    format!("CRC-32 of its records is {computed:#010x}, its header says {recorded:#010x}")
}

impl Tail {
    /// Stops decoding `src` at output position `pos` of `dst` (a block boundary reached by
    /// `decoder`); the deferred record is `dst[range]`, which runs past `pos`.
    pub fn defer(
        decoder: &Decoder,
        src: &[u8],
        dst: &[u8],
        pos: usize,
        range: std::ops::Range<usize>,
    ) -> Self {
        let base = pos.saturating_sub(WINDOW).min(range.start);
        let (decoder, rest) = decoder.rebase(src, base);
        Self {
            head: dst.get(base..pos).unwrap_or_default().to_vec(),
            rest,
            decoder,
            range: range.start - base..range.end - base,
            crc: None,
        }
    }

    /// Checks, at each decode, that the output ends with CRC-32 `crc`, `hasher` having been fed
    /// the output up to the position this tail was deferred at.
    pub fn check_crc(&mut self, hasher: crc32fast::Hasher, crc: u32) {
        self.crc = Some((hasher, crc));
    }

    /// The record's bytes decoded so far.
    pub fn prefix(&self) -> &[u8] {
        self.head.get(self.range.start..).unwrap_or_default()
    }

    /// Decodes the rest and calls `f` with the record's bytes (decoded into a buffer kept per
    /// thread, so a frame costs no fresh, zeroed allocation).
    pub fn with<T>(&self, f: impl FnOnce(&[u8]) -> T) -> Result<T, String> {
        thread_local! {
            static OUT: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
        }
        OUT.with(|out| match out.try_borrow_mut() {
            Ok(mut out) => self.decode_into(&mut out, f),
            Err(_) => self.decode_into(&mut Vec::new(), f),
        })
    }

    fn decode_into<T>(&self, out: &mut Vec<u8>, f: impl FnOnce(&[u8]) -> T) -> Result<T, String> {
        let n = self.range.end;
        if out.len() < n {
            out.resize(n, 0);
        }
        let out = &mut out[..n];
        out[..self.head.len()].copy_from_slice(&self.head);
        let mut decoder = self.decoder.clone();
        let pos = decoder.decode(&self.rest, out, self.head.len(), n)?;
        if pos != n {
            return Err(format!(
                "lz4: input ends {} bytes short of the record's end",
                n - pos
            ));
        }
        if let Some((hasher, crc)) = &self.crc {
            let mut hasher = hasher.clone();
            hasher.update(&out[self.head.len()..]);
            let computed = hasher.finalize();
            if computed != *crc {
                return Err(crc_mismatch(computed, *crc));
            }
        }
        Ok(f(&out[self.range.clone()]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lz4_flex::frame::{BlockMode, BlockSize, FrameEncoder, FrameInfo};
    use std::io::Write;

    fn data(n: usize) -> Vec<u8> {
        // Compressible with long-range repeats, plus some noise.
        (0..n)
            .map(|i| ((i / 3) % 251) as u8 ^ if i % 97 == 0 { (i % 13) as u8 } else { 0 })
            .collect()
    }

    fn encode(info: FrameInfo, raw: &[u8]) -> Vec<u8> {
        let mut e = FrameEncoder::with_frame_info(info, Vec::new());
        e.write_all(raw).unwrap();
        e.finish().unwrap()
    }

    #[test]
    fn every_frame_layout_round_trips() {
        let raw = data(300_000);
        for mode in [BlockMode::Linked, BlockMode::Independent] {
            for checksums in [false, true] {
                let info = FrameInfo::new()
                    .block_size(BlockSize::Max64KB)
                    .block_mode(mode)
                    .block_checksums(checksums)
                    .content_checksum(checksums)
                    .content_size(checksums.then_some(raw.len() as u64));
                let packed = encode(info, &raw);
                let mut out = vec![0; raw.len()];
                assert_eq!(decompress_frames(&packed, &mut out).unwrap(), raw.len());
                assert_eq!(out, raw);
            }
        }
    }

    #[test]
    fn concatenated_and_skippable_frames() {
        let (a, b) = (data(70_000), data(1_000));
        let mut packed = encode(FrameInfo::new(), &a);
        packed.extend_from_slice(&0x184D_2A53u32.to_le_bytes());
        packed.extend_from_slice(&3u32.to_le_bytes());
        packed.extend_from_slice(b"xyz");
        packed.extend(encode(FrameInfo::new(), &b));
        let mut out = vec![0; a.len() + b.len()];
        assert_eq!(decompress_frames(&packed, &mut out).unwrap(), out.len());
        assert_eq!(&out[..a.len()], &a[..]);
        assert_eq!(&out[a.len()..], &b[..]);
    }

    #[test]
    fn a_deferred_tail_decodes_to_the_same_bytes() {
        let raw = data(400_000);
        for mode in [BlockMode::Linked, BlockMode::Independent] {
            let info = FrameInfo::new()
                .block_size(BlockSize::Max64KB)
                .block_mode(mode);
            let packed = encode(info, &raw);
            let mut out = vec![0; raw.len()];
            let mut dec = Decoder::default();
            let pos = dec.decode(&packed, &mut out, 0, 150_000).unwrap();
            assert!((150_000..raw.len()).contains(&pos));
            let tail = Tail::defer(&dec, &packed, &out, pos, 140_000..raw.len());
            assert_eq!(tail.prefix(), &raw[140_000..pos]);
            assert!(tail.with(|b| b == &raw[140_000..]).unwrap());
            // Going on in place gives the same.
            let end = dec.decode(&packed, &mut out, pos, raw.len()).unwrap();
            assert_eq!((end, &out[..]), (raw.len(), &raw[..]));
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let raw = data(200_000);
        let packed = encode(FrameInfo::new(), &raw);
        let mut out = vec![0; raw.len()];
        // Input cut inside the data: an error, or fewer bytes than asked for.
        for cut in [3, 6, 12, packed.len() / 2, packed.len() - 5] {
            let r = decompress_frames(&packed[..cut], &mut out);
            assert!(r.map_or(true, |n| n < raw.len()), "cut {cut}");
        }
        // Only the end mark lost: every byte was there.
        let n = decompress_frames(&packed[..packed.len() - 1], &mut out).unwrap();
        assert_eq!((n, &out[..]), (raw.len(), &raw[..]));
        let mut small = vec![0; raw.len() - 1];
        assert!(decompress_frames(&packed, &mut small).is_err());
        let mut bad = packed.clone();
        bad[0] ^= 1;
        assert!(decompress_frames(&bad, &mut out)
            .unwrap_err()
            .contains("magic"));
    }
}
