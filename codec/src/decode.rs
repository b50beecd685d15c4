//! The video decoders behind one small trait: AV1 with `re_rav1d` (rerun's build of rav1d, the
//! Rust port of dav1d; pure Rust here, without its nasm assembly, so nothing but cargo builds
//! it) and H.264 with `openh264` (Cisco's decoder, its C++ source compiled by the crate's build
//! script). Samples go in in decode order; pictures come out in presentation order, 8-bit 4:2:0.

use re_rav1d::dav1d;

use crate::yuv::Yuv420;

/// The codecs we decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// AV1 (`av01`; temporal units of OBUs).
    Av1,
    /// H.264 (`avc1` with an `avcC` record, or Annex B with in-band parameter sets).
    H264,
}

/// A decoder fed one MP4 sample (an access unit / temporal unit) at a time.
pub trait Decode: Send {
    /// Decodes one sample; every picture that comes out is handed to `out`.
    fn push(&mut self, sample: &[u8], out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String>;
    /// Hands out the pictures still held back for reordering.
    fn flush(&mut self, out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String>;
    /// Forgets the stream so far, to start again at a keyframe of the same codec; false when
    /// the decoder cannot, and a new one must be made.
    fn reset(&mut self) -> bool;
}

/// A fresh decoder for `codec`; `config` is the sample entry's configuration record (`avcC`
/// for H.264: its length size and parameter sets), empty for Annex B samples that carry their
/// parameter sets in band (`foxglove_msgs/CompressedVideo`).
pub fn new_decoder(codec: Codec, config: &[u8]) -> Result<Box<dyn Decode>, String> {
    Ok(match codec {
        Codec::Av1 => Box::new(Av1::new()?),
        Codec::H264 => Box::new(H264::new(config)?),
    })
}

struct Av1 {
    dec: dav1d::Decoder,
}

impl Av1 {
    fn new() -> Result<Self, String> {
        let mut settings = dav1d::Settings::new();
        // The loader decodes many samples in parallel: one thread per decoder, no frame delay.
        settings.set_n_threads(1);
        settings.set_max_frame_delay(1);
        let dec =
            dav1d::Decoder::with_settings(&settings).map_err(|e| format!("AV1 decoder: {e}"))?;
        Ok(Av1 { dec })
    }

    fn drain(&mut self, out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
        loop {
            match self.dec.get_picture() {
                Ok(p) => emit_av1(&p, out)?,
                Err(dav1d::Error::Again) => return Ok(()),
                Err(e) => return Err(format!("AV1: {e}")),
            }
        }
    }
}

fn emit_av1(p: &dav1d::Picture, out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
    use dav1d::{PixelLayout, PlanarImageComponent as C};
    if p.bit_depth() != 8 || p.pixel_layout() != PixelLayout::I420 {
        return Err(format!(
            "AV1 picture in {:?} at {} bits: only 8-bit 4:2:0 (yuv420p) is decoded",
            p.pixel_layout(),
            p.bit_depth()
        ));
    }
    let (y, u, v) = (p.plane(C::Y), p.plane(C::U), p.plane(C::V));
    let planes = Yuv420 {
        width: p.width() as usize,
        height: p.height() as usize,
        y: &y,
        u: &u,
        v: &v,
        y_stride: p.stride(C::Y) as usize,
        uv_stride: p.stride(C::U) as usize,
    };
    planes.check()?;
    out(planes);
    Ok(())
}

impl Decode for Av1 {
    fn push(&mut self, sample: &[u8], out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
        let mut sent = self.dec.send_data(sample.to_vec(), None, None, None);
        loop {
            match sent {
                Ok(()) => return self.drain(out),
                Err(dav1d::Error::Again) => {
                    // Pictures must be taken out before the rest of the data goes in.
                    self.drain(out)?;
                    sent = self.dec.send_pending_data();
                }
                Err(e) => return Err(format!("AV1: {e}")),
            }
        }
    }

    fn flush(&mut self, out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
        self.drain(out)
    }

    fn reset(&mut self) -> bool {
        // dav1d's seek: drops every picture and reference, keeps its allocations (opening a
        // decoder per group of pictures cost most of the decoding time with LeRobot's GOP of 2).
        self.dec.flush();
        true
    }
}

struct H264 {
    dec: openh264::decoder::Decoder,
    /// Bytes of each NAL unit's length prefix in the samples (`avcC`), 0 for Annex B samples.
    nal_length: usize,
    /// SPS and PPS in Annex B, sent before the first sample.
    headers: Option<Vec<u8>>,
    annex_b: Vec<u8>,
}

impl H264 {
    fn new(config: &[u8]) -> Result<Self, String> {
        let dec = openh264::decoder::Decoder::new().map_err(|e| format!("H.264 decoder: {e}"))?;
        let (nal_length, headers) = if config.is_empty() {
            (0, None)
        } else {
            let (n, h) = parse_avcc(config)?;
            (n, Some(h))
        };
        Ok(H264 {
            dec,
            nal_length,
            headers,
            annex_b: Vec::new(),
        })
    }
}

/// `AVCDecoderConfigurationRecord` → (NAL length size, SPS and PPS as Annex B).
pub fn parse_avcc(c: &[u8]) -> Result<(usize, Vec<u8>), String> {
    let bad = || "H.264 configuration (avcC) cut short".to_string();
    if c.len() < 6 || c[0] != 1 {
        return Err("H.264 configuration (avcC) is not version 1".into());
    }
    let nal_length = usize::from(c[4] & 3) + 1;
    let mut out = Vec::new();
    let mut at = 5;
    for count_mask in [0x1F, 0xFF] {
        let n = usize::from(*c.get(at).ok_or_else(bad)? & count_mask);
        at += 1;
        for _ in 0..n {
            let len = usize::from(u16::from_be_bytes([
                *c.get(at).ok_or_else(bad)?,
                *c.get(at + 1).ok_or_else(bad)?,
            ]));
            let nal = c.get(at + 2..at + 2 + len).ok_or_else(bad)?;
            out.extend_from_slice(&[0, 0, 0, 1]);
            out.extend_from_slice(nal);
            at += 2 + len;
        }
    }
    Ok((nal_length, out))
}

/// Length-prefixed NAL units → Annex B (start codes), appended to `out`.
fn to_annex_b(sample: &[u8], nal_length: usize, out: &mut Vec<u8>) -> Result<(), String> {
    let mut at = 0;
    while at < sample.len() {
        let len_bytes = sample
            .get(at..at + nal_length)
            .ok_or("H.264 sample ends inside a NAL length")?;
        let len = len_bytes
            .iter()
            .fold(0usize, |a, &b| (a << 8) | usize::from(b));
        at += nal_length;
        let nal = sample
            .get(at..at + len)
            .ok_or_else(|| format!("H.264 NAL unit of {len} bytes runs past its sample"))?;
        out.extend_from_slice(&[0, 0, 0, 1]);
        out.extend_from_slice(nal);
        at += len;
    }
    Ok(())
}

fn emit_h264(
    p: &openh264::decoder::DecodedYUV<'_>,
    out: &mut dyn FnMut(Yuv420<'_>),
) -> Result<(), String> {
    use openh264::formats::YUVSource;
    let (w, h) = p.dimensions();
    let (ys, us, _) = p.strides();
    let planes = Yuv420 {
        width: w,
        height: h,
        y: p.y(),
        u: p.u(),
        v: p.v(),
        y_stride: ys,
        uv_stride: us,
    };
    planes.check()?;
    out(planes);
    Ok(())
}

impl Decode for H264 {
    fn push(&mut self, sample: &[u8], out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
        self.annex_b.clear();
        if let Some(h) = self.headers.take() {
            self.annex_b.extend_from_slice(&h);
        }
        if self.nal_length == 0 {
            self.annex_b.extend_from_slice(sample);
        } else {
            to_annex_b(sample, self.nal_length, &mut self.annex_b)?;
        }
        // No flush after each sample (the crate's default): that would hand out pictures held
        // back for B-frame reordering out of order.
        let options = openh264::decoder::DecodeOptions::new()
            .flush_after_decode(openh264::decoder::Flush::NoFlush);
        match self.dec.decode_with_options(&self.annex_b, options) {
            Ok(Some(p)) => emit_h264(&p, out),
            Ok(None) => Ok(()),
            Err(e) => Err(format!("H.264: {e}")),
        }
    }

    fn flush(&mut self, out: &mut dyn FnMut(Yuv420<'_>)) -> Result<(), String> {
        let rest = self
            .dec
            .flush_remaining()
            .map_err(|e| format!("H.264: {e}"))?;
        for p in &rest {
            emit_h264(p, out)?;
        }
        Ok(())
    }

    fn reset(&mut self) -> bool {
        // OpenH264 has no call that drops held-back pictures: a new decoder is made.
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn avcc_gives_parameter_sets_and_length_size() {
        // version 1, profile 66, compat 0, level 30, 4-byte lengths, 1 SPS of 3 bytes, 1 PPS of 2.
        let c = [1, 66, 0, 30, 0xFF, 0xE1, 0, 3, 0x67, 1, 2, 1, 0, 2, 0x68, 9];
        let (n, h) = parse_avcc(&c).unwrap();
        assert_eq!(n, 4);
        assert_eq!(h, [0, 0, 0, 1, 0x67, 1, 2, 0, 0, 0, 1, 0x68, 9]);
        assert!(parse_avcc(&c[..9]).is_err());
        let mut out = Vec::new();
        to_annex_b(&[0, 0, 0, 2, 0x65, 7, 0, 0, 0, 1, 0x41], 4, &mut out).unwrap();
        assert_eq!(out, [0, 0, 0, 1, 0x65, 7, 0, 0, 0, 1, 0x41]);
        assert!(to_annex_b(&[0, 0, 0, 9, 0x65], 4, &mut Vec::new()).is_err());
    }
}
