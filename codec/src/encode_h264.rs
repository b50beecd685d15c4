//! H.264 encoding with `openh264` at a constant QP: its buffer-based rate control, which only
//! moves the QP within the QP range, is given a range of one value (`crf` clamped to 1–51;
//! openh264 reads a minimum of 0 as "use the defaults"), with adaptive quantization, scene
//! change detection and frame skipping off. Every `gop`-th frame is forced to an IDR; there are no B-frames. Annex B output
//! becomes 4-byte length-prefixed samples and the first SPS/PPS the `avcC` record.

use openh264::encoder::{
    BitRate, Complexity, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, QpRange,
    RateControlMode, UsageType, VuiConfig,
};
use openh264::formats::YUVSlices;
use openh264::OpenH264API;

use crate::encoding::{EncodeError, Planes, Samples, VideoSettings};

/// NAL unit types.
const NAL_IDR: u8 = 5;
const NAL_SPS: u8 = 7;
const NAL_PPS: u8 = 8;

pub(crate) struct H264Encoder {
    enc: Encoder,
    gop: usize,
    /// The first SPS and PPS (without start codes), for `avcC`.
    sps: Option<Vec<u8>>,
    pps: Option<Vec<u8>>,
}

fn fail(e: impl std::fmt::Display) -> EncodeError {
    EncodeError::Encoder {
        codec: "H.264",
        message: e.to_string(),
    }
}

impl H264Encoder {
    pub fn new(s: &VideoSettings) -> Result<Self, EncodeError> {
        let qp = s.crf.clamp(1, 51);
        let config = EncoderConfig::new()
            .usage_type(UsageType::CameraVideoRealTime)
            .rate_control_mode(RateControlMode::Bufferbased)
            // Required to be set, unused at one QP.
            .bitrate(BitRate::from_bps(100_000_000))
            .qp(QpRange::new(qp, qp))
            .skip_frames(false)
            .max_frame_rate(FrameRate::from_hz(s.fps as f32))
            .intra_frame_period(IntraFramePeriod::from_num_frames(s.gop))
            .scene_change_detect(false)
            .adaptive_quantization(false)
            .background_detection(false)
            .complexity(Complexity::Medium)
            // One thread: the same bitstream every run, cameras encode in parallel anyway.
            .num_threads(1)
            .vui(VuiConfig::bt601());
        let enc = Encoder::with_api_config(OpenH264API::from_source(), config).map_err(fail)?;
        Ok(H264Encoder {
            enc,
            gop: s.gop as usize,
            sps: None,
            pps: None,
        })
    }

    /// Encodes frame number `index`.
    pub fn push(
        &mut self,
        p: &Planes<'_>,
        index: usize,
        out: &mut Samples,
    ) -> Result<(), EncodeError> {
        let cw = p.width / 2;
        let yuv = YUVSlices::new((p.y, p.u, p.v), (p.width, p.height), (p.width, cw, cw));
        if index % self.gop == 0 {
            self.enc.force_intra_frame();
        }
        let bits = self.enc.encode(&yuv).map_err(fail)?;
        if matches!(bits.frame_type(), FrameType::Skip | FrameType::Invalid) {
            return Err(fail(format!(
                "frame {index} was not encoded ({:?})",
                bits.frame_type()
            )));
        }
        let (mut sample, mut key) = (Vec::new(), false);
        for layer in (0..bits.num_layers()).filter_map(|l| bits.layer(l)) {
            for nal in (0..layer.nal_count()).filter_map(|n| layer.nal_unit(n)) {
                let nal = strip_start_code(nal);
                let Some(&header) = nal.first() else { continue };
                let kind = header & 0x1F;
                let known = match kind {
                    NAL_SPS => &mut self.sps,
                    NAL_PPS => &mut self.pps,
                    _ => {
                        key |= kind == NAL_IDR;
                        append_nal(&mut sample, nal)?;
                        continue;
                    }
                };
                // Parameter sets go to `avcC`; only ones that differ from it stay in band.
                match known {
                    None => *known = Some(nal.to_vec()),
                    Some(k) if k.as_slice() == nal => {}
                    Some(_) => append_nal(&mut sample, nal)?,
                }
            }
        }
        if sample.is_empty() {
            return Err(fail(format!("frame {index} gave no picture")));
        }
        out.samples.push(sample);
        out.keyframes.push(key);
        Ok(())
    }

    /// The `avcC` record.
    pub fn finish(self) -> Result<Vec<u8>, EncodeError> {
        match (self.sps, self.pps) {
            (Some(sps), Some(pps)) => avcc(&sps, &pps),
            _ => Err(fail("no SPS and PPS came out")),
        }
    }
}

/// A NAL unit without its Annex B start code (3 or 4 bytes).
fn strip_start_code(nal: &[u8]) -> &[u8] {
    let zeros = nal.iter().take_while(|&&b| b == 0).count();
    if zeros >= 2 && nal.get(zeros) == Some(&1) {
        &nal[zeros + 1..]
    } else {
        nal
    }
}

fn append_nal(sample: &mut Vec<u8>, nal: &[u8]) -> Result<(), EncodeError> {
    let len = u32::try_from(nal.len()).map_err(|_| fail("NAL unit over 4 GB"))?;
    sample.extend_from_slice(&len.to_be_bytes());
    sample.extend_from_slice(nal);
    Ok(())
}

/// AVCDecoderConfigurationRecord: one SPS, one PPS, 4-byte NAL lengths.
fn avcc(sps: &[u8], pps: &[u8]) -> Result<Vec<u8>, EncodeError> {
    if sps.len() < 4 {
        return Err(fail(format!("SPS of {} bytes", sps.len())));
    }
    let len16 = |n: &[u8]| u16::try_from(n.len()).map_err(|_| fail("parameter set over 64 KB"));
    let mut c = vec![1, sps[1], sps[2], sps[3], 0xFC | 3, 0xE0 | 1];
    c.extend_from_slice(&len16(sps)?.to_be_bytes());
    c.extend_from_slice(sps);
    c.push(1);
    c.extend_from_slice(&len16(pps)?.to_be_bytes());
    c.extend_from_slice(pps);
    if matches!(sps[1], 100 | 110 | 122 | 144) {
        // High profiles: chroma_format 4:2:0, 8-bit luma and chroma, no SPS extensions.
        c.extend_from_slice(&[0xFC | 1, 0xF8, 0xF8, 0]);
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::parse_avcc;

    #[test]
    fn start_codes_are_stripped_and_avcc_parses_back() {
        assert_eq!(strip_start_code(&[0, 0, 0, 1, 0x67, 9]), [0x67, 9]);
        assert_eq!(strip_start_code(&[0, 0, 1, 0x68]), [0x68]);
        assert_eq!(strip_start_code(&[0x41, 0]), [0x41, 0]);
        let c = avcc(&[0x67, 66, 0xC0, 30, 1], &[0x68, 2]).unwrap();
        let (n, h) = parse_avcc(&c).unwrap();
        assert_eq!(n, 4);
        assert_eq!(h, [0, 0, 0, 1, 0x67, 66, 0xC0, 30, 1, 0, 0, 0, 1, 0x68, 2]);
        let high = avcc(&[0x67, 100, 0, 30], &[0x68]).unwrap();
        assert_eq!(high[high.len() - 4..], [0xFD, 0xF8, 0xF8, 0]);
    }
}
