//! Decoding and encoding of colour, 16-bit depth and 16-bit label images,
//! with errors that name the file.

use std::io::BufWriter;
use std::path::Path;

use image::{DynamicImage, ImageBuffer, Luma, Rgb};
use opengs_geometry::Intrinsics;

use crate::DatasetError;

fn open(path: &Path) -> Result<DynamicImage, DatasetError> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| DatasetError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| DatasetError::io(path, e))?;
    reader.decode().map_err(|e| DatasetError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn check_size(
    path: &Path,
    img: &DynamicImage,
    width: u32,
    height: u32,
) -> Result<(), DatasetError> {
    if img.width() != width || img.height() != height {
        return Err(DatasetError::SizeMismatch {
            path: path.to_path_buf(),
            width,
            height,
            found_width: img.width(),
            found_height: img.height(),
        });
    }
    Ok(())
}

/// `Missing` naming the index file that lists `path` when the file is not there.
pub(crate) fn check_exists(path: &Path, listed_in: &str) -> Result<(), DatasetError> {
    if path.is_file() {
        return Ok(());
    }
    Err(DatasetError::invalid(
        path,
        format!("not found (listed in {listed_in})"),
    ))
}

/// Compares an image's size (read from its header only) with the camera's, so a wrong or
/// missing calibration is named when the dataset is opened; `camera` says where `k` came from.
pub(crate) fn check_image_size(
    path: &Path,
    k: &Intrinsics,
    camera: &str,
) -> Result<(), DatasetError> {
    let (w, h) = image::ImageReader::open(path)
        .map_err(|e| DatasetError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| DatasetError::io(path, e))?
        .into_dimensions()
        .map_err(|e| DatasetError::Image {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    if (w, h) != (k.width, k.height) {
        return Err(DatasetError::invalid(
            path,
            format!("image is {w}x{h}, but {camera} is {}x{}", k.width, k.height),
        ));
    }
    Ok(())
}

/// Reads a colour image (PNG or JPEG) as row-major RGB8 of the expected size.
pub(crate) fn read_rgb(path: &Path, width: u32, height: u32) -> Result<Vec<u8>, DatasetError> {
    let img = open(path)?;
    check_size(path, &img, width, height)?;
    Ok(img.into_rgb8().into_raw())
}

/// Reads a single-channel 16-bit PNG (depth or labels) of the expected size.
pub(crate) fn read_u16(path: &Path, width: u32, height: u32) -> Result<Vec<u16>, DatasetError> {
    let img = open(path)?;
    check_size(path, &img, width, height)?;
    match img {
        DynamicImage::ImageLuma16(buf) => Ok(buf.into_raw()),
        other => Err(DatasetError::invalid(
            path,
            format!(
                "expected a 16-bit single-channel image, found {:?}",
                other.color()
            ),
        )),
    }
}

/// A failed write names the file and what stopped it (a full disk, a missing folder), not a
/// decoding problem.
fn encode_err(path: &Path, e: image::ImageError) -> DatasetError {
    match e {
        image::ImageError::IoError(source) => DatasetError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => DatasetError::invalid(path, format!("cannot encode image: {other}")),
    }
}

pub(crate) fn write_u16_png(
    path: &Path,
    width: u32,
    height: u32,
    data: &[u16],
) -> Result<(), DatasetError> {
    let buf: ImageBuffer<Luma<u16>, &[u16]> = ImageBuffer::from_raw(width, height, data)
        .ok_or_else(|| DatasetError::invalid(path, "buffer size does not match image size"))?;
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| encode_err(path, e))
}

pub(crate) fn write_rgb_png(
    path: &Path,
    width: u32,
    height: u32,
    data: &[u8],
) -> Result<(), DatasetError> {
    let buf: ImageBuffer<Rgb<u8>, &[u8]> = ImageBuffer::from_raw(width, height, data)
        .ok_or_else(|| DatasetError::invalid(path, "buffer size does not match image size"))?;
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| encode_err(path, e))
}

pub(crate) fn write_rgb_jpeg(
    path: &Path,
    width: u32,
    height: u32,
    data: &[u8],
    quality: u8,
) -> Result<(), DatasetError> {
    let file = std::fs::File::create(path).map_err(|e| DatasetError::io(path, e))?;
    let mut encoder =
        image::codecs::jpeg::JpegEncoder::new_with_quality(BufWriter::new(file), quality);
    encoder
        .encode(data, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| encode_err(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_names_the_file_and_the_io_error_not_decoding() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("no_such_folder").join("000083.png");
        let err = write_u16_png(&path, 2, 1, &[1, 2]).expect_err("no folder");
        let text = err.to_string();
        assert!(matches!(err, DatasetError::Io { .. }), "{err:?}");
        assert!(
            text.contains("000083.png") && !text.contains("decode"),
            "{text}"
        );
    }
}
