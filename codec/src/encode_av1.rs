//! AV1 encoding with `rav1e` (pure Rust, built without its nasm assembly): 8-bit 4:2:0,
//! BT.601 limited range signalled, a fixed quantizer, a keyframe every `gop` frames (minimum
//! and maximum interval both `gop`, scene detection off) and `low_latency`, so frames are
//! neither reordered nor held back past the lookahead: one packet (temporal unit) per frame.

use rav1e::prelude::{
    ChromaSampling, ColorDescription, ColorPrimaries, Config, Context, EncoderConfig,
    EncoderStatus, FrameType, MatrixCoefficients, Packet, PixelRange, Rational,
    SceneDetectionSpeed, SpeedSettings, TransferCharacteristics,
};

use crate::encoding::{EncodeError, Planes, Samples, VideoSettings};

/// OBU types.
const OBU_SEQUENCE_HEADER: u8 = 1;
const OBU_TEMPORAL_DELIMITER: u8 = 2;

pub(crate) struct Av1Encoder {
    ctx: Context<u8>,
    /// Input number of the next packet expected.
    next: u64,
    /// The first sequence header OBU, for `av1C`.
    sequence_header: Option<Vec<u8>>,
}

fn fail(e: impl std::fmt::Display) -> EncodeError {
    EncodeError::Encoder {
        codec: "AV1",
        message: e.to_string(),
    }
}

/// rav1e's quantizer (0–255) for a crf on AV1's 0–63 scale.
pub(crate) fn quantizer(crf: u8) -> usize {
    (usize::from(crf) * 255 + 31) / 63
}

impl Av1Encoder {
    pub fn new(s: &VideoSettings, width: u32, height: u32) -> Result<Self, EncodeError> {
        let mut enc = EncoderConfig::with_speed_preset(s.av1_speed);
        enc.width = width as usize;
        enc.height = height as usize;
        enc.bit_depth = 8;
        enc.chroma_sampling = ChromaSampling::Cs420;
        enc.pixel_range = PixelRange::Limited;
        enc.color_description = Some(ColorDescription {
            color_primaries: ColorPrimaries::BT601,
            transfer_characteristics: TransferCharacteristics::BT601,
            matrix_coefficients: MatrixCoefficients::BT601,
        });
        // Rate control only (timing info is not written): fps × 1000 ticks per second.
        let ticks = (s.fps * 1000.0).round().max(1.0) as u64;
        enc.time_base = Rational::new(1000, ticks);
        enc.set_key_frame_interval(u64::from(s.gop), u64::from(s.gop));
        enc.low_latency = true;
        enc.quantizer = quantizer(s.crf);
        enc.bitrate = 0;
        enc.speed_settings = SpeedSettings::from_preset(s.av1_speed);
        enc.speed_settings.scene_detection_mode = SceneDetectionSpeed::None;
        let ctx = Config::new()
            .with_encoder_config(enc)
            .new_context()
            .map_err(fail)?;
        Ok(Av1Encoder {
            ctx,
            next: 0,
            sequence_header: None,
        })
    }

    pub fn push(&mut self, p: &Planes<'_>, out: &mut Samples) -> Result<(), EncodeError> {
        let mut frame = self.ctx.new_frame();
        let cw = p.width.div_ceil(2);
        frame.planes[0].copy_from_raw_u8(p.y, p.width, 1);
        frame.planes[1].copy_from_raw_u8(p.u, cw, 1);
        frame.planes[2].copy_from_raw_u8(p.v, cw, 1);
        self.ctx.send_frame(frame).map_err(fail)?;
        self.drain(out)
    }

    /// Takes out the packets that are ready.
    fn drain(&mut self, out: &mut Samples) -> Result<(), EncodeError> {
        loop {
            match self.ctx.receive_packet() {
                Ok(packet) => self.take(packet, out)?,
                Err(EncoderStatus::Encoded) => {}
                Err(EncoderStatus::NeedMoreData | EncoderStatus::LimitReached) => return Ok(()),
                Err(e) => return Err(fail(e)),
            }
        }
    }

    fn take(&mut self, packet: Packet<u8>, out: &mut Samples) -> Result<(), EncodeError> {
        if packet.input_frameno != self.next {
            return Err(fail(format!(
                "packet of frame {} where frame {} was due",
                packet.input_frameno, self.next
            )));
        }
        self.next += 1;
        let mut sample = Vec::with_capacity(packet.data.len());
        for obu in obus(&packet.data)? {
            match obu_type(obu) {
                OBU_TEMPORAL_DELIMITER => continue,
                OBU_SEQUENCE_HEADER if self.sequence_header.is_none() => {
                    self.sequence_header = Some(obu.to_vec());
                }
                _ => {}
            }
            sample.extend_from_slice(obu);
        }
        out.samples.push(sample);
        out.keyframes.push(packet.frame_type == FrameType::KEY);
        Ok(())
    }

    /// Flushes the encoder; the `av1C` record.
    pub fn finish(mut self, out: &mut Samples) -> Result<Vec<u8>, EncodeError> {
        self.ctx.flush();
        self.drain(out)?;
        let Some(sequence_header) = self.sequence_header else {
            return Err(fail("no sequence header came out"));
        };
        // rav1e's 4 bytes (marker, version, profile, level, tier, bit depth, subsampling; no
        // initial presentation delay), then the sequence header OBU as configOBUs.
        let mut config = self.ctx.container_sequence_header();
        config.extend_from_slice(&sequence_header);
        Ok(config)
    }
}

fn obu_type(obu: &[u8]) -> u8 {
    (obu[0] >> 3) & 0x0F
}

/// Splits a temporal unit into its OBUs (each with its size field, as rav1e writes them).
fn obus(mut data: &[u8]) -> Result<Vec<&[u8]>, EncodeError> {
    let mut out = Vec::new();
    while let Some(&header) = data.first() {
        if header & 0x02 == 0 {
            return Err(fail("OBU without a size field"));
        }
        let mut at = 1 + usize::from(header & 0x04 != 0);
        let mut size = 0usize;
        for i in 0..8 {
            let b = *data.get(at).ok_or_else(|| fail("OBU cut short"))?;
            at += 1;
            size |= usize::from(b & 0x7F) << (7 * i);
            if b & 0x80 == 0 {
                break;
            }
        }
        let end = at
            .checked_add(size)
            .filter(|&e| e <= data.len())
            .ok_or_else(|| fail("OBU runs past its packet"))?;
        out.push(&data[..end]);
        data = &data[end..];
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crf_maps_to_rav1e_quantizer_and_obus_split() {
        assert_eq!(
            [0, 30, 63].map(quantizer),
            [0, 121, 255],
            "crf × 255 / 63, rounded"
        );
        // A temporal delimiter (size 0), then an OBU of type 6 with a 2-byte LEB128 size 130.
        let mut tu = vec![0x12, 0, 0x32, 0x82, 0x01];
        tu.extend([7; 130]);
        let split = obus(&tu).unwrap();
        assert_eq!(split.len(), 2);
        assert_eq!(
            (obu_type(split[0]), obu_type(split[1])),
            (OBU_TEMPORAL_DELIMITER, 6)
        );
        assert_eq!(split[1].len(), 133);
        assert!(obus(&tu[..100]).is_err());
        assert!(obus(&[0x30]).is_err());
    }
}
