//! Camera messages → rerun images. Raw frames keep their pixel layout (rerun shows BGR(A)
//! natively, so a ZED frame is copied once, never converted); compressed frames and dataset
//! JPEGs are handed over still encoded. Only a frame wider than `max_width` is decoded and
//! resized (Lanczos3, the converter's resampler).

use rerun::components::MediaType;
use rerun::datatypes::{ChannelDatatype, ColorModel};
use rerun::{EncodedImage, Image};
use scaledp_converter::images::{jpeg, resize, resized_rgb, view_to_rgb, ImageView, Rgb};
use scaledp_converter::Serialization;
use scaledp_schema::msg::{CompressedImage, Image as RosImage};
use scaledp_schema::RosMessage;

/// JPEG quality of frames re-encoded after downsampling.
const RESIZED_JPEG_QUALITY: u8 = 90;

/// A frame ready to log.
pub(crate) enum Frame {
    /// Pixels.
    Raw(Image),
    /// Encoded bytes (JPEG or PNG).
    Encoded(EncodedImage),
    /// Depth values and their meter.
    Depth(Box<rerun::DepthImage>),
}

impl Frame {
    /// Logs the frame at `path` on the stream's current time.
    pub fn log(
        &self,
        rec: &rerun::RecordingStream,
        path: &str,
    ) -> rerun::RecordingStreamResult<()> {
        match self {
            Self::Raw(i) => rec.log(path, i),
            Self::Encoded(e) => rec.log(path, e),
            Self::Depth(d) => rec.log(path, d.as_ref()),
        }
    }
}

/// The size a frame `width × height` is shown at with `max_width` (aspect kept).
pub(crate) fn shown_size(width: u32, height: u32, max_width: Option<u32>) -> (u32, u32) {
    match max_width {
        Some(m) if m > 0 && width > m => {
            let h = (f64::from(height) * f64::from(m) / f64::from(width)).round();
            (m, (h as u32).max(1))
        }
        _ => (width, height),
    }
}

fn rgb_frame(rgb: Rgb) -> Frame {
    Frame::Raw(Image::from_color_model_and_bytes(
        rgb.data,
        [rgb.width, rgb.height],
        ColorModel::RGB,
        ChannelDatatype::U8,
    ))
}

/// A raw image, resized to fit `max_width` or passed through in its own layout.
pub(crate) fn raw_frame(view: &ImageView<'_>, max_width: Option<u32>) -> Result<Frame, String> {
    let (w, h) = shown_size(view.width, view.height, max_width);
    if (w, h) != (view.width, view.height) {
        return resized_rgb(view, w, h).map(rgb_frame).map_err(String::from);
    }
    let (model, channels) = match view.encoding {
        "rgb8" => (ColorModel::RGB, 3),
        "bgr8" => (ColorModel::BGR, 3),
        "rgba8" => (ColorModel::RGBA, 4),
        "bgra8" => (ColorModel::BGRA, 4),
        "mono8" => (ColorModel::L, 1),
        other => return Err(format!("unsupported image encoding '{other}'")),
    };
    let row = view.width as usize * channels;
    let bytes = row * view.height as usize;
    if view.step as usize != row || view.data.len() < bytes {
        // Padded rows (or a short buffer, which view_to_rgb reports): repack as RGB.
        return view_to_rgb(view).map(rgb_frame).map_err(String::from);
    }
    Ok(Frame::Raw(Image::from_color_model_and_bytes(
        view.data[..bytes].to_vec(),
        [view.width, view.height],
        model,
        ChannelDatatype::U8,
    )))
}

/// The media type of encoded image bytes, from their magic number.
fn media_type(bytes: &[u8]) -> Option<MediaType> {
    if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        Some(MediaType::jpeg())
    } else if bytes.starts_with(b"\x89PNG") {
        Some(MediaType::png())
    } else {
        None
    }
}

/// Encoded image bytes (JPEG/PNG), downsampled and re-encoded as JPEG only when wider than
/// `max_width`.
pub(crate) fn encoded_frame(bytes: &[u8], max_width: Option<u32>) -> Result<Frame, String> {
    if max_width.is_some() {
        let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        let (w, h) = reader.into_dimensions().map_err(|e| e.to_string())?;
        let (sw, sh) = shown_size(w, h, max_width);
        if (sw, sh) != (w, h) {
            let img = image::load_from_memory(bytes).map_err(|e| e.to_string())?;
            let rgb = img.to_rgb8();
            let full = Rgb {
                width: rgb.width(),
                height: rgb.height(),
                data: rgb.into_raw(),
            };
            let small = resize(&full, sw, sh)?;
            let out = jpeg(&small, RESIZED_JPEG_QUALITY)?;
            return Ok(Frame::Encoded(
                EncodedImage::new(out).with_media_type(MediaType::jpeg()),
            ));
        }
    }
    let image = EncodedImage::new(bytes.to_vec());
    Ok(Frame::Encoded(match media_type(bytes) {
        Some(m) => image.with_media_type(m),
        None => image,
    }))
}

/// A camera message (`sensor_msgs/Image` or `CompressedImage`, CDR or ROS 1) → its capture
/// stamp (ns; 0 when the header has none) and the frame to log (depth as a depth image).
pub(crate) fn message_frame(
    message_type: &str,
    serialization: Serialization,
    data: &[u8],
    max_width: Option<u32>,
) -> Result<(u64, Frame), String> {
    if let Some(depth) = crate::depth::depth_message(message_type, serialization, data, max_width) {
        return depth.map(|(t, d)| (t, Frame::Depth(Box::new(d))));
    }
    let compressed = message_type.ends_with("/CompressedImage");
    match (serialization, compressed) {
        (Serialization::Cdr, false) => {
            let stamp = scaledp_schema::msg::header_stamp(data).map_or(0, |t| t.as_ns());
            let view = ImageView::from_cdr(data).map_err(String::from)?;
            Ok((stamp, raw_frame(&view, max_width)?))
        }
        (Serialization::Ros1, false) => {
            let img = scaledp_converter::ros1::decode::image(data).map_err(|e| e.to_string())?;
            Ok((img.header.stamp.as_ns(), owned_raw(&img, max_width)?))
        }
        (Serialization::Cdr, true) => {
            let c = CompressedImage::from_cdr(data).map_err(|e| e.to_string())?;
            Ok((c.header.stamp.as_ns(), encoded_frame(&c.data, max_width)?))
        }
        (Serialization::Ros1, true) => {
            let c = scaledp_converter::ros1::decode::compressed_image(data)
                .map_err(|e| e.to_string())?;
            Ok((c.header.stamp.as_ns(), encoded_frame(&c.data, max_width)?))
        }
    }
}

fn owned_raw(img: &RosImage, max_width: Option<u32>) -> Result<Frame, String> {
    raw_frame(
        &ImageView {
            width: img.width,
            height: img.height,
            encoding: &img.encoding,
            step: img.step,
            data: &img.data,
        },
        max_width,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_keep_the_aspect() {
        assert_eq!(shown_size(1280, 720, Some(320)), (320, 180));
        assert_eq!(shown_size(320, 240, Some(640)), (320, 240));
        assert_eq!(shown_size(320, 240, None), (320, 240));
        assert_eq!(shown_size(4000, 1, Some(10)), (10, 1));
    }

    #[test]
    fn media_types_from_magic() {
        assert_eq!(
            media_type(&[0xff, 0xd8, 0xff, 0xe0]),
            Some(MediaType::jpeg())
        );
        assert_eq!(media_type(b"\x89PNG\r\n"), Some(MediaType::png()));
        assert_eq!(media_type(b"GIF8"), None);
    }
}
