//! Pixels of ROS 2 image messages as an [`crate::RgbdFrame`] holds them: colour as RGB8,
//! depth as u16 units of `1/depth_scale` metres (0 = no depth).
//!
//! `sensor_msgs/msg/Image` is `height` rows of `step` bytes (`step ≥ width × bytes per
//! pixel`; bytes past a row's pixels are padding); multi-byte samples are big-endian when
//! `is_bigendian` is set. Colour: `rgb8`, `bgr8`, `rgba8`, `bgra8` (alpha dropped), `mono8`
//! (grey to R = G = B). Depth: `16UC1` (or `mono16`) in millimetres, `32FC1` in metres
//! (NaN, ±inf and ≤ 0 are no depth). A depth that does not fit the u16 range at the
//! frame's scale (13.1 m at 5000 units/m) is no depth too. `sensor_msgs/msg/CompressedImage`
//! with a `format` naming jpeg or png decodes to RGB8 (grey expanded).

use crate::ros_msgs::{CompressedImage, Image};

/// A raw image encoding we read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PixelFormat {
    Rgb8,
    Bgr8,
    Rgba8,
    Bgra8,
    Mono8,
    /// Depth in millimetres (`16UC1`, `mono16`).
    DepthMm16,
    /// Depth in metres (`32FC1`).
    DepthM32,
}

/// The encodings of [`PixelFormat::parse`], for error messages.
pub(crate) const COLOUR_ENCODINGS: &str = "rgb8, bgr8, rgba8, bgra8, mono8";
pub(crate) const DEPTH_ENCODINGS: &str = "16UC1 (mm), mono16 (mm), 32FC1 (m)";

impl PixelFormat {
    /// The format of an `Image.encoding` string; `None` for one we do not read.
    pub fn parse(encoding: &str) -> Option<Self> {
        Some(match encoding {
            "rgb8" => Self::Rgb8,
            "bgr8" => Self::Bgr8,
            "rgba8" => Self::Rgba8,
            "bgra8" => Self::Bgra8,
            "mono8" => Self::Mono8,
            "16UC1" | "mono16" => Self::DepthMm16,
            "32FC1" => Self::DepthM32,
            _ => return None,
        })
    }

    pub fn is_depth(self) -> bool {
        matches!(self, Self::DepthMm16 | Self::DepthM32)
    }

    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Mono8 => 1,
            Self::DepthMm16 => 2,
            Self::Rgb8 | Self::Bgr8 => 3,
            Self::Rgba8 | Self::Bgra8 | Self::DepthM32 => 4,
        }
    }
}

/// The format of an image and the checks of its layout: a known encoding, `step` holding a
/// row's pixels, and exactly `height × step` data bytes.
pub(crate) fn check_layout(img: &Image) -> Result<PixelFormat, String> {
    let format = PixelFormat::parse(&img.encoding).ok_or_else(|| {
        format!(
            "unknown image encoding '{}' (colour: {COLOUR_ENCODINGS}; depth: {DEPTH_ENCODINGS})",
            img.encoding.escape_debug()
        )
    })?;
    if img.width == 0 || img.height == 0 {
        return Err(format!("empty image ({}x{})", img.width, img.height));
    }
    let row = img.width as u64 * format.bytes_per_pixel() as u64;
    if (img.step as u64) < row {
        return Err(format!(
            "step {} is shorter than a row of {} {} pixels ({row} bytes)",
            img.step, img.width, img.encoding
        ));
    }
    let expected = img.height as u64 * img.step as u64;
    if img.data.0.len() as u64 != expected {
        return Err(format!(
            "{} data bytes, but height × step = {} × {} = {expected}",
            img.data.0.len(),
            img.height,
            img.step
        ));
    }
    if img.is_bigendian > 1 {
        return Err(format!("is_bigendian is {}, not 0 or 1", img.is_bigendian));
    }
    Ok(format)
}

/// The rows of an image checked by [`check_layout`], padding cut off.
fn rows<'a>(img: &'a Image, format: PixelFormat) -> impl Iterator<Item = &'a [u8]> {
    let row = img.width as usize * format.bytes_per_pixel();
    img.data
        .0
        .chunks_exact(img.step as usize)
        .map(move |r| &r[..row])
}

/// A colour image as row-major RGB8.
pub(crate) fn decode_colour(img: &Image) -> Result<Vec<u8>, String> {
    let format = check_layout(img)?;
    if format.is_depth() {
        return Err(format!(
            "encoding '{}' is depth, not colour ({COLOUR_ENCODINGS})",
            img.encoding
        ));
    }
    let mut out = Vec::with_capacity(img.width as usize * img.height as usize * 3);
    for row in rows(img, format) {
        match format {
            PixelFormat::Rgb8 => out.extend_from_slice(row),
            PixelFormat::Bgr8 => row
                .chunks_exact(3)
                .for_each(|p| out.extend_from_slice(&[p[2], p[1], p[0]])),
            PixelFormat::Rgba8 => row
                .chunks_exact(4)
                .for_each(|p| out.extend_from_slice(&p[..3])),
            PixelFormat::Bgra8 => row
                .chunks_exact(4)
                .for_each(|p| out.extend_from_slice(&[p[2], p[1], p[0]])),
            PixelFormat::Mono8 => row.iter().for_each(|&g| out.extend_from_slice(&[g, g, g])),
            PixelFormat::DepthMm16 | PixelFormat::DepthM32 => {}
        }
    }
    Ok(out)
}

/// Metres to depth units at `scale` units per metre; 0 (no depth) for what is not a
/// positive finite depth or does not fit a u16.
pub(crate) fn metres_to_units(m: f64, scale: f64) -> u16 {
    if !(m.is_finite() && m > 0.0) {
        return 0;
    }
    let v = (m * scale).round();
    if v <= u16::MAX as f64 {
        v as u16
    } else {
        0
    }
}

/// A depth image as row-major u16 units of `1/scale` metres; millimetres at 1000 units per
/// metre are copied unchanged.
pub(crate) fn decode_depth(img: &Image, scale: f32) -> Result<Vec<u16>, String> {
    let format = check_layout(img)?;
    let big = img.is_bigendian == 1;
    let scale = scale as f64;
    let mut out = Vec::with_capacity(img.width as usize * img.height as usize);
    for row in rows(img, format) {
        match format {
            PixelFormat::DepthMm16 => {
                let mm = row.chunks_exact(2).map(|b| {
                    let b = [b[0], b[1]];
                    if big {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    }
                });
                if scale == 1000.0 {
                    out.extend(mm);
                } else {
                    out.extend(mm.map(|d| metres_to_units(d as f64 / 1000.0, scale)));
                }
            }
            PixelFormat::DepthM32 => out.extend(row.chunks_exact(4).map(|b| {
                let b = [b[0], b[1], b[2], b[3]];
                let m = if big {
                    f32::from_be_bytes(b)
                } else {
                    f32::from_le_bytes(b)
                };
                metres_to_units(m as f64, scale)
            })),
            _ => {
                return Err(format!(
                    "encoding '{}' is colour, not depth ({DEPTH_ENCODINGS})",
                    img.encoding
                ))
            }
        }
    }
    Ok(out)
}

/// The codec a `CompressedImage.format` names (`jpeg`, `png`, or e.g.
/// `rgb8; jpeg compressed bgr8`).
pub(crate) fn compressed_codec(format: &str) -> Result<image::ImageFormat, String> {
    let f = format.to_ascii_lowercase();
    if f.contains("compresseddepth") {
        return Err(format!(
            "format '{format}' is compressedDepth, which is not read: record the raw depth \
             image (sensor_msgs/msg/Image 16UC1 or 32FC1)"
        ));
    }
    if f.contains("jpeg") || f.contains("jpg") {
        Ok(image::ImageFormat::Jpeg)
    } else if f.contains("png") {
        Ok(image::ImageFormat::Png)
    } else {
        Err(format!(
            "compressed format '{}' is neither jpeg nor png",
            format.escape_debug()
        ))
    }
}

fn compressed_reader<'a>(
    img: &'a CompressedImage,
) -> Result<image::ImageReader<std::io::Cursor<&'a [u8]>>, String> {
    let codec = compressed_codec(&img.format)?;
    Ok(image::ImageReader::with_format(
        std::io::Cursor::new(img.data.0),
        codec,
    ))
}

/// Width and height of a compressed image, from its header only.
pub(crate) fn compressed_size(img: &CompressedImage) -> Result<(u32, u32), String> {
    compressed_reader(img)?
        .into_dimensions()
        .map_err(|e| format!("cannot read the {} header: {e}", img.format))
}

/// A compressed colour image as RGB8 of the expected size (larger images are refused
/// before they are decoded).
pub(crate) fn decode_compressed_colour(
    img: &CompressedImage,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, String> {
    let (w, h) = compressed_size(img)?;
    if (w, h) != (width, height) {
        return Err(format!(
            "compressed image is {w}x{h}, expected {width}x{height}"
        ));
    }
    let mut reader = compressed_reader(img)?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(width);
    limits.max_image_height = Some(height);
    reader.limits(limits);
    let decoded = reader
        .decode()
        .map_err(|e| format!("cannot decode the {} image: {e}", img.format))?;
    Ok(decoded.into_rgb8().into_raw())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::Bytes;
    use crate::ros_msgs::Header;

    fn image<'a>(encoding: &str, w: u32, h: u32, step: u32, data: &'a [u8]) -> Image<'a> {
        Image {
            header: Header::default(),
            height: h,
            width: w,
            encoding: encoding.into(),
            is_bigendian: 0,
            step,
            data: Bytes(data),
        }
    }

    #[test]
    fn colour_orders_and_padding() {
        // 2x2 with one byte of padding per row.
        let bgr = [1, 2, 3, 4, 5, 6, 0, 7, 8, 9, 10, 11, 12, 0];
        let img = image("bgr8", 2, 2, 7, &bgr);
        assert_eq!(
            decode_colour(&img),
            Ok(vec![3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10])
        );
        let mono = [5, 6, 9, 7, 8, 9];
        assert_eq!(
            decode_colour(&image("mono8", 2, 2, 3, &mono)),
            Ok(vec![5, 5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8])
        );
        let bgra = [1, 2, 3, 255, 4, 5, 6, 0];
        assert_eq!(
            decode_colour(&image("bgra8", 2, 1, 8, &bgra)),
            Ok(vec![3, 2, 1, 6, 5, 4])
        );
        assert_eq!(
            decode_colour(&image("rgba8", 2, 1, 8, &bgra)),
            Ok(vec![1, 2, 3, 4, 5, 6])
        );
    }

    #[test]
    fn depth_units_and_endianness() {
        let mm = [0xe8, 0x03, 0x00, 0x00]; // 1000, 0 little-endian
        assert_eq!(
            decode_depth(&image("16UC1", 2, 1, 4, &mm), 1000.0),
            Ok(vec![1000, 0])
        );
        assert_eq!(
            decode_depth(&image("16UC1", 2, 1, 4, &mm), 5000.0),
            Ok(vec![5000, 0])
        );
        let mut img = image("16UC1", 2, 1, 4, &[0x03, 0xe8, 0, 1]);
        img.is_bigendian = 1;
        assert_eq!(decode_depth(&img, 1000.0), Ok(vec![1000, 1]));
        let mut m = Vec::new();
        for v in [1.5f32, f32::NAN, f32::INFINITY, -1.0, 0.0, 20.0] {
            m.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(
            decode_depth(&image("32FC1", 6, 1, 24, &m), 5000.0),
            Ok(vec![7500, 0, 0, 0, 0, 0])
        );
    }

    #[test]
    fn layout_errors_say_what_is_wrong() {
        let e = decode_colour(&image("yuv422", 1, 1, 2, &[0, 0])).expect_err("unknown");
        assert!(e.contains("yuv422") && e.contains("rgb8"), "{e}");
        let e = decode_colour(&image("rgb8", 2, 2, 6, &[0; 11])).expect_err("short");
        assert!(e.contains("11 data bytes") && e.contains("12"), "{e}");
        let e = decode_colour(&image("rgb8", 2, 2, 5, &[0; 10])).expect_err("step");
        assert!(e.contains("step 5"), "{e}");
        let e = decode_depth(&image("rgb8", 1, 1, 3, &[0; 3]), 1000.0).expect_err("colour");
        assert!(e.contains("not depth"), "{e}");
        let e = decode_colour(&image("16UC1", 1, 1, 2, &[0; 2])).expect_err("depth");
        assert!(e.contains("not colour"), "{e}");
        // Huge dimensions must not overflow.
        let e = decode_colour(&image("rgba8", u32::MAX, u32::MAX, u32::MAX, &[0; 4]))
            .expect_err("huge");
        assert!(e.contains("step"), "{e}");
    }

    #[test]
    fn compressed_formats() {
        assert_eq!(compressed_codec("jpeg"), Ok(image::ImageFormat::Jpeg));
        assert_eq!(
            compressed_codec("rgb8; jpeg compressed bgr8"),
            Ok(image::ImageFormat::Jpeg)
        );
        assert_eq!(compressed_codec("png"), Ok(image::ImageFormat::Png));
        assert!(compressed_codec("16UC1; compressedDepth png").is_err());
        assert!(compressed_codec("tiff").is_err());
    }
}
