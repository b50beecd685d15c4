//! Encode → MP4 → `re_mp4` → decode, per codec, the way the converter writes an episode-
//! concatenated camera file and the loader reads it back.

use crate::{mp4_file, new_decoder, Codec, EncodedVideo, VideoEncoder, VideoSettings, Yuv420};

const W: usize = 64;
const H: usize = 48;
const FRAMES: usize = 30;
const FPS: f64 = 30.0;

/// Frame `k`: colour gradients moving right and down under a grey checker (8-pixel squares,
/// ±30 levels on all three channels, so its edges are luma only) moving diagonally.
fn frame(k: usize) -> Vec<u8> {
    let mut rgb = Vec::with_capacity(W * H * 3);
    for y in 0..H {
        for x in 0..W {
            let checker = if ((x + k) / 8 + (y + k) / 8) % 2 == 0 {
                30
            } else {
                0
            };
            rgb.push((40 + (x + 2 * k) * 3 / 2 + checker) as u8);
            rgb.push((40 + (y + k) * 2 + checker) as u8);
            rgb.push((150 - (x + y) + checker) as u8);
        }
    }
    rgb
}

fn encode(settings: VideoSettings, frames: std::ops::Range<usize>) -> EncodedVideo {
    let mut enc = VideoEncoder::new(settings, W as u32, H as u32).unwrap();
    for k in frames {
        enc.push_rgb(&frame(k)).unwrap();
    }
    enc.finish().unwrap()
}

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0 * 255.0 / mse.max(1e-9)).log10()
}

fn find(file: &[u8], kind: &[u8; 4]) -> Option<usize> {
    file.windows(4).position(|w| w == kind)
}

/// Two pieces (frames 0–14, 15–29) in one file, read back and decoded; the worst and mean PSNR.
fn round_trip(codec: Codec) -> (f64, f64) {
    let settings = VideoSettings::lerobot(codec, FPS);
    let (a, b) = (encode(settings, 0..15), encode(settings, 15..FRAMES));
    assert_eq!(
        a.config, b.config,
        "pieces encoded apart share a configuration"
    );
    let file = mp4_file(&[&a, &b], FPS).unwrap();
    let (moov, mdat) = (find(&file, b"moov").unwrap(), find(&file, b"mdat").unwrap());
    assert!(moov < mdat, "faststart");
    assert!(find(&file, b"edts").is_none(), "no edit list");

    let mp4 = re_mp4::Mp4::read_bytes(&file).unwrap();
    assert_eq!(mp4.tracks().len(), 1);
    let track = mp4.tracks().values().next().unwrap();
    assert_eq!(track.kind, Some(re_mp4::TrackKind::Video));
    let stsd = &track.trak(&mp4).mdia.minf.stbl.stsd.contents;
    match codec {
        Codec::Av1 => assert!(matches!(stsd, re_mp4::StsdBoxContent::Av01(_))),
        Codec::H264 => assert!(matches!(stsd, re_mp4::StsdBoxContent::Avc1(_))),
    }
    assert_eq!((track.width, track.height), (W as u16, H as u16));
    assert_eq!(track.timescale, 30_000);
    let config = track.raw_codec_config(&mp4).unwrap();
    assert_eq!(config, a.config);
    assert_eq!(track.samples.len(), FRAMES);
    let originals: Vec<&Vec<u8>> = a.samples.iter().chain(&b.samples).collect();
    for (k, s) in track.samples.iter().enumerate() {
        // Every 2nd frame of each piece: 0, 2, … 14, then 15, 17, … 29.
        assert_eq!(s.is_sync, k % 2 == usize::from(k >= 15), "sample {k}");
        assert_eq!(s.composition_timestamp, k as i64 * 1000, "sample {k}");
        assert_eq!(s.decode_timestamp, k as i64 * 1000, "sample {k}");
        assert_eq!(s.duration, 1000);
        let bytes = &file[s.offset as usize..][..s.size as usize];
        assert_eq!(bytes, originals[k].as_slice(), "sample {k}");
    }

    let mut dec = new_decoder(codec, &config).unwrap();
    let mut pictures = Vec::new();
    let mut keep = |p: Yuv420<'_>| {
        assert_eq!((p.width, p.height), (W, H));
        let mut rgb = Vec::new();
        p.write_rgb(&mut rgb);
        pictures.push(rgb);
    };
    for s in &track.samples {
        dec.push(&file[s.offset as usize..][..s.size as usize], &mut keep)
            .unwrap();
    }
    dec.flush(&mut keep).unwrap();
    assert_eq!(pictures.len(), FRAMES);
    let scores: Vec<f64> = (0..FRAMES).map(|k| psnr(&pictures[k], &frame(k))).collect();
    let worst = scores.iter().copied().fold(f64::INFINITY, f64::min);
    let mean = scores.iter().sum::<f64>() / FRAMES as f64;
    let bytes: usize = originals.iter().map(|s| s.len()).sum();
    eprintln!("{codec:?}: PSNR worst {worst:.2} dB, mean {mean:.2} dB, {bytes} bytes of samples");
    (worst, mean)
}

#[test]
fn h264_pieces_mux_read_back_and_decode_close_to_the_source() {
    let (worst, _) = round_trip(Codec::H264);
    assert!(worst >= 30.0, "PSNR {worst:.2} dB");
}

#[test]
fn av1_pieces_mux_read_back_and_decode_close_to_the_source() {
    let (worst, _) = round_trip(Codec::Av1);
    assert!(worst >= 30.0, "PSNR {worst:.2} dB");
}

#[test]
fn pieces_of_another_codec_size_or_configuration_do_not_mux() {
    let h264 = VideoSettings::lerobot(Codec::H264, FPS);
    let a = encode(h264, 0..2);
    let av1 = encode(VideoSettings::lerobot(Codec::Av1, FPS), 0..2);
    let mut smaller = VideoEncoder::new(h264, 32, 24).unwrap();
    smaller.push_rgb(&[128; 32 * 24 * 3]).unwrap();
    let smaller = smaller.finish().unwrap();
    let mut other_config = a.clone();
    other_config.config.push(0);
    for (b, what) in [
        (&av1, "codec"),
        (&smaller, "size"),
        (&other_config, "configuration"),
    ] {
        let err = mp4_file(&[&a, &a, b], FPS).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("piece 2 differs from piece 0 in its {what}: one track needs equal codec, size and configuration")
        );
    }
    assert_eq!(
        mp4_file(&[], FPS).unwrap_err().to_string(),
        "no video to write: no frames"
    );
}

/// Frames per second of each encoder (release build, all cores); not a check.
#[test]
#[ignore = "a measurement: cargo test --release -p scaledp-codec encode_speed -- --ignored --nocapture"]
fn encode_speed() {
    for (w, h, n) in [(84usize, 84usize, 120usize), (320, 240, 60)] {
        let frames: Vec<Vec<u8>> = (0..n)
            .map(|k| {
                (0..w * h)
                    .flat_map(|i| {
                        let (x, y) = (i % w + 2 * k, i / w + k);
                        [
                            (x * 3) as u8,
                            (y * 2) as u8,
                            (((x / 8 + y / 8) % 2) * 150) as u8,
                        ]
                    })
                    .collect()
            })
            .collect();
        let runs = [
            (Codec::H264, 0),
            (Codec::Av1, 6),
            (Codec::Av1, 8),
            (Codec::Av1, 10),
        ];
        for (codec, speed) in runs {
            let settings = VideoSettings {
                av1_speed: speed,
                ..VideoSettings::lerobot(codec, FPS)
            };
            let start = std::time::Instant::now();
            let mut enc = VideoEncoder::new(settings, w as u32, h as u32).unwrap();
            frames.iter().for_each(|f| enc.push_rgb(f).unwrap());
            let out = enc.finish().unwrap();
            let s = start.elapsed().as_secs_f64();
            let bytes: usize = out.samples.iter().map(Vec::len).sum();
            eprintln!(
                "{w}×{h} {codec:?} speed {speed}: {:.1} frames/s, {} bytes/frame",
                n as f64 / s,
                bytes / n
            );
        }
    }
}
