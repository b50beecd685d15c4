//! Camera frames → RGB → resized → JPEG, plus the per-channel statistics LeRobot keeps: the
//! image path of the converter (and of [`crate::live`]). Raw `sensor_msgs/Image` pixels in
//! bgra8, bgr8, rgb8, rgba8 or mono8 (honouring `step`) or a JPEG/PNG `CompressedImage`, resized
//! with a Lanczos3 convolution, encoded as baseline JPEG.

use std::path::Path;

use fast_image_resize as fr;
use scaledp_schema::msg::Header;
use scaledp_schema::rig::DepthEncoding;
use scaledp_schema::{CdrReader, RosMessage};

use crate::decode::Frame;
use crate::error::{Error, Result};
use crate::resample::{lanczos3, reorder, with_resizer};
use crate::source::{RawMessage, Serialization};

mod histogram;
mod rgb;
pub use histogram::ChannelHistogram;
pub use rgb::Rgb;

/// Why a camera frame could not become RGB or JPEG.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The `sensor_msgs/Image` CDR payload is malformed.
    #[error(transparent)]
    Cdr(#[from] scaledp_schema::Error),
    /// A pixel encoding the converter does not read (e.g. `16UC1`, `yuv422`).
    #[error("unsupported image encoding '{0}'")]
    Encoding(String),
    /// No pixels: a zero width or height.
    #[error("empty image {width}×{height}")]
    Empty {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
    },
    /// Width, height, `step` and the data length do not fit together.
    #[error("{encoding} image {width}×{height}: {problem}")]
    Layout {
        /// Pixel encoding.
        encoding: String,
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
        /// What does not fit, e.g. "3000 data bytes, but 24 rows of step 128 need 3072".
        problem: String,
    },
    /// A compressed frame that could not be decoded.
    #[error("{format} image: {reason}")]
    Compressed {
        /// The message's `format`, e.g. `jpeg`, `png`.
        format: String,
        /// The decoder's reason.
        reason: String,
    },
    /// Resizing failed (sizes the resizer refuses).
    #[error("resize: {0}")]
    Resize(String),
    /// JPEG encoding failed (a side above 65535, …).
    #[error("jpeg: {0}")]
    Jpeg(String),
}

/// Kept for callers that report errors as text.
impl From<ImageError> for String {
    fn from(e: ImageError) -> Self {
        e.to_string()
    }
}

type ImageResult<T> = std::result::Result<T, ImageError>;

/// Output size and JPEG quality of encoded frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EncodeSpec {
    /// Output width.
    pub width: u32,
    /// Output height.
    pub height: u32,
    /// JPEG quality (1–100).
    pub quality: u8,
    /// Keep the resized RGB pixels instead of encoding them to JPEG (for a dataset whose
    /// cameras are stored as video: the episode's frames are encoded together).
    pub raw: bool,
}

/// A camera frame resized and JPEG-encoded (or kept as RGB, see [`EncodeSpec::raw`]), with the
/// histogram of its resized pixels; or a depth image (see [`crate::depth`]), its values resized
/// by nearest neighbour.
#[derive(Debug, Clone)]
pub struct EncodedFrame {
    /// JPEG bytes, or packed RGB8 rows when the spec asks for raw pixels; for a depth image its
    /// values, little-endian (`u16` millimetres or `f32` metres).
    pub bytes: Vec<u8>,
    /// Pixel statistics of the resized frame (empty for depth).
    pub histogram: ChannelHistogram,
    /// The image as the message held it, before resizing.
    pub source: SourceImage,
    /// The depth encoding, for a depth image (`16UC1` / `32FC1` raw or `compressedDepth`).
    pub depth: Option<DepthEncoding>,
}

/// A frame's image as its message held it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SourceImage {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// A raw image's `encoding` (`bgra8`, `16UC1`, …) or a compressed one's `format`.
    pub encoding: String,
}

/// A raw image borrowed from its message (`sensor_msgs/Image` fields, pixels not copied).
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Pixel encoding, e.g. `bgra8`.
    pub encoding: &'a str,
    /// Bytes per row.
    pub step: u32,
    /// The pixels.
    pub data: &'a [u8],
}

impl<'a> ImageView<'a> {
    /// Parses a CDR `sensor_msgs/msg/Image` payload without copying its pixels.
    pub fn from_cdr(payload: &'a [u8]) -> ImageResult<Self> {
        let mut r = CdrReader::new(payload)?;
        Header::read(&mut r)?;
        let height = r.u32()?;
        let width = r.u32()?;
        let encoding = r.str()?;
        r.u8()?;
        let step = r.u32()?;
        let data = r.bytes()?;
        Ok(Self {
            width,
            height,
            encoding,
            step,
            data,
        })
    }

    /// (bytes per pixel, source index of R, G, B) of the encoding.
    fn layout(&self) -> ImageResult<(usize, [usize; 3])> {
        Ok(match self.encoding {
            "rgb8" => (3, [0, 1, 2]),
            "bgr8" => (3, [2, 1, 0]),
            "rgba8" => (4, [0, 1, 2]),
            "bgra8" => (4, [2, 1, 0]),
            "mono8" => (1, [0, 0, 0]),
            other => return Err(ImageError::Encoding(other.into())),
        })
    }

    /// Checks the size, step and data length; returns the layout. Sizes come from the message,
    /// so every product is checked (a 4294967295-square image overflows 64 bits).
    fn check(&self) -> ImageResult<(usize, [usize; 3])> {
        let (channels, order) = self.layout()?;
        let (w, h, step) = (
            self.width as usize,
            self.height as usize,
            self.step as usize,
        );
        if w == 0 || h == 0 {
            return Err(ImageError::Empty {
                width: self.width,
                height: self.height,
            });
        }
        let bad = |problem: String| ImageError::Layout {
            encoding: self.encoding.into(),
            width: self.width,
            height: self.height,
            problem,
        };
        crate::raw_rows::checked_row_bytes(w, h, step, channels, self.data.len()).map_err(bad)?;
        Ok((channels, order))
    }
}

/// Decodes a raw image to RGB, honouring `step` (row padding).
pub fn view_to_rgb(img: &ImageView<'_>) -> ImageResult<Rgb> {
    let (channels, order) = img.check()?;
    let (w, h) = (img.width as usize, img.height as usize);
    let mut out = Vec::with_capacity(w * h * 3);
    for row in img.data.chunks(img.step as usize).take(h) {
        for px in row[..w * channels].chunks_exact(channels) {
            out.extend_from_slice(&[px[order[0]], px[order[1]], px[order[2]]]);
        }
    }
    Ok(Rgb {
        width: img.width,
        height: img.height,
        data: out,
    })
}

/// A raw image resized to `width × height` RGB. Rows without padding of 3- or 4-byte pixels are
/// resized as stored (alpha ignored, never premultiplied) and only the small result is
/// reordered to RGB: the same pixels as [`view_to_rgb`] then [`resize`], without converting the
/// full-size frame.
pub fn resized_rgb(img: &ImageView<'_>, width: u32, height: u32) -> ImageResult<Rgb> {
    let (channels, order) = img.check()?;
    let (w, h) = (img.width, img.height);
    let packed = img.step as usize == w as usize * channels;
    let pixel = match channels {
        3 => fr::PixelType::U8x3,
        4 => fr::PixelType::U8x4,
        _ => return resize(&view_to_rgb(img)?, width, height),
    };
    if !packed || (w, h) == (width, height) {
        return resize(&view_to_rgb(img)?, width, height);
    }
    let bytes = img.step as usize * h as usize;
    let from = fr::images::ImageRef::new(w, h, &img.data[..bytes], pixel)
        .map_err(|e| ImageError::Resize(e.to_string()))?;
    let mut to = fr::images::Image::new(width, height, pixel);
    let options = fr::ResizeOptions::new()
        .resize_alg(fr::ResizeAlg::Convolution(lanczos3()))
        .use_alpha(false);
    with_resizer(|r| r.resize(&from, &mut to, &options))
        .map_err(|e| ImageError::Resize(e.to_string()))?;
    let mut data = vec![0; width as usize * height as usize * 3];
    match (channels, order) {
        (4, [2, 1, 0]) => reorder::<4, 2, 1, 0>(to.buffer(), &mut data),
        (4, _) => reorder::<4, 0, 1, 2>(to.buffer(), &mut data),
        (_, [2, 1, 0]) => reorder::<3, 2, 1, 0>(to.buffer(), &mut data),
        _ => data.copy_from_slice(to.buffer()),
    }
    Ok(Rgb {
        width,
        height,
        data,
    })
}

/// Resized RGB → JPEG (or the pixels themselves) and histogram.
fn finish(small: Rgb, spec: &EncodeSpec, source: SourceImage) -> ImageResult<EncodedFrame> {
    let mut histogram = ChannelHistogram::default();
    histogram.add(&small);
    let bytes = if spec.raw {
        small.data
    } else {
        jpeg(&small, spec.quality)?
    };
    Ok(EncodedFrame {
        bytes,
        histogram,
        source,
        depth: None,
    })
}

/// A depth image resized by nearest neighbour to the spec's size, as stored.
fn finish_depth(d: &crate::depth::DepthImage, encoding: String, spec: &EncodeSpec) -> EncodedFrame {
    EncodedFrame {
        bytes: d.resized(spec.width, spec.height).to_le_bytes(),
        histogram: ChannelHistogram::default(),
        source: SourceImage {
            width: d.width,
            height: d.height,
            encoding,
        },
        depth: Some(d.encoding()),
    }
}

/// One camera message of `path` (raw or compressed, either serialization) → resized JPEG and
/// histogram. CDR raw images are read in place; others are decoded through [`crate::decode`].
/// A depth image (raw `16UC1` / `32FC1`, or `compressedDepth`) becomes its values instead,
/// resized by nearest neighbour (see [`crate::depth`]).
pub fn encode_message(
    path: &Path,
    topic: &str,
    message_type: &str,
    log_time_ns: u64,
    serialization: Serialization,
    data: &[u8],
    spec: &EncodeSpec,
) -> Result<EncodedFrame> {
    let err = |e: ImageError| Error::Message {
        path: path.into(),
        topic: topic.into(),
        log_time_ns,
        reason: e.to_string(),
    };
    let message_err = |reason: String| Error::Message {
        path: path.into(),
        topic: topic.into(),
        log_time_ns,
        reason,
    };
    let compressed = message_type.ends_with("/CompressedImage");
    if serialization == Serialization::Cdr && !compressed {
        let view = ImageView::from_cdr(data).map_err(err)?;
        if crate::depth::raw_depth_encoding(view.encoding).is_some() {
            let raw = crate::depth::RawDepth::from_cdr(data).map_err(message_err)?;
            let d = raw.decode().map_err(message_err)?;
            return Ok(finish_depth(&d, view.encoding.to_string(), spec));
        }
        let small = resized_rgb(&view, spec.width, spec.height).map_err(err)?;
        let source = SourceImage {
            width: view.width,
            height: view.height,
            encoding: view.encoding.to_string(),
        };
        return finish(small, spec, source).map_err(err);
    }
    let m = RawMessage {
        topic: topic.into(),
        message_type: message_type.into(),
        log_time_ns,
        data: data.to_vec(),
        serialization,
    };
    let f = crate::decode::frame(path, &m)?;
    match &f {
        Frame::Raw(img) if crate::depth::raw_depth_encoding(&img.encoding).is_some() => {
            let raw = crate::depth::RawDepth {
                width: img.width,
                height: img.height,
                encoding: &img.encoding,
                is_bigendian: img.is_bigendian,
                step: img.step,
                data: &img.data,
            };
            let d = raw.decode().map_err(message_err)?;
            return Ok(finish_depth(&d, img.encoding.clone(), spec));
        }
        Frame::Compressed(c) if crate::depth::is_compressed_depth(&c.format) => {
            let d =
                crate::depth::decode_compressed_depth(&c.format, &c.data).map_err(message_err)?;
            let encoding = c.format.split(';').next().unwrap_or_default().trim();
            return Ok(finish_depth(&d, encoding.to_string(), spec));
        }
        _ => {}
    }
    let source_encoding = match &f {
        Frame::Raw(img) => img.encoding.clone(),
        Frame::Compressed(c) => c.format.clone(),
    };
    let rgb = to_rgb(&f).map_err(err)?;
    let source = SourceImage {
        width: rgb.width,
        height: rgb.height,
        encoding: source_encoding,
    };
    let small = resize(&rgb, spec.width, spec.height).map_err(err)?;
    finish(small, spec, source).map_err(err)
}

/// Decodes a frame to RGB, honouring `step` (row padding) for raw images.
pub(crate) fn to_rgb(frame: &Frame) -> ImageResult<Rgb> {
    match frame {
        Frame::Raw(img) => view_to_rgb(&ImageView {
            width: img.width,
            height: img.height,
            encoding: &img.encoding,
            step: img.step,
            data: &img.data,
        }),
        Frame::Compressed(c) => {
            let img = decode_compressed(&c.data).map_err(|reason| ImageError::Compressed {
                format: c.format.clone(),
                reason,
            })?;
            let rgb = img.to_rgb8();
            Ok(Rgb {
                width: rgb.width(),
                height: rgb.height(),
                data: rgb.into_raw(),
            })
        }
    }
}

/// Most pixels of a compressed frame decoded (a 8K frame has 33 M): a header claiming more is
/// refused before anything is allocated for it.
const MAX_COMPRESSED_PIXELS: u64 = 64 << 20;

/// Decodes a JPEG or PNG, refusing sizes a camera does not send (a decompression bomb: a few
/// bytes whose header claims 60000×60000).
fn decode_compressed(data: &[u8]) -> Result<image::DynamicImage, String> {
    let reader = image::ImageReader::new(std::io::Cursor::new(data))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let (w, h) = reader.into_dimensions().map_err(|e| e.to_string())?;
    if u64::from(w) * u64::from(h) > MAX_COMPRESSED_PIXELS {
        return Err(format!(
            "{w}×{h} pixels, more than the {} M the converter decodes",
            MAX_COMPRESSED_PIXELS >> 20
        ));
    }
    image::load_from_memory(data).map_err(|e| e.to_string())
}

/// Resizes with a Lanczos3 convolution (antialiased when shrinking); a no-op at the same size.
pub fn resize(src: &Rgb, width: u32, height: u32) -> ImageResult<Rgb> {
    if src.width == width && src.height == height {
        return Ok(src.clone());
    }
    let from = fr::images::ImageRef::new(src.width, src.height, &src.data, fr::PixelType::U8x3)
        .map_err(|e| ImageError::Resize(e.to_string()))?;
    let mut to = fr::images::Image::new(width, height, fr::PixelType::U8x3);
    let options = fr::ResizeOptions::new().resize_alg(fr::ResizeAlg::Convolution(lanczos3()));
    with_resizer(|r| r.resize(&from, &mut to, &options))
        .map_err(|e| ImageError::Resize(e.to_string()))?;
    Ok(Rgb {
        width,
        height,
        data: to.into_vec(),
    })
}

/// Encodes RGB as baseline JPEG at `quality` (1–100).
pub fn jpeg(src: &Rgb, quality: u8) -> ImageResult<Vec<u8>> {
    let mut out = Vec::with_capacity(src.data.len() / 8);
    let encoder = jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100));
    let side = |v: u32| {
        u16::try_from(v).map_err(|_| {
            ImageError::Jpeg(format!(
                "{}×{} is beyond 65535 a side",
                src.width, src.height
            ))
        })
    };
    let (w, h) = (side(src.width)?, side(src.height)?);
    encoder
        .encode(&src.data, w, h, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| ImageError::Jpeg(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests;
