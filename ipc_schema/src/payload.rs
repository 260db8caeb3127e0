use std::mem::MaybeUninit;

use crate::SchemaError;

/// Every payload section starts on this alignment, so typed views need no copy.
pub const ALIGN: usize = 8;

/// Length of a section of `n` elements of `T`, padded to [`ALIGN`].
pub(crate) fn section_len<T>(n: usize) -> usize {
    (n * std::mem::size_of::<T>()).div_ceil(ALIGN) * ALIGN
}

/// Writes typed sections into a loaned, uninitialised payload in place.
pub struct PayloadWriter<'a> {
    buf: &'a mut [MaybeUninit<u8>],
    pos: usize,
}

impl<'a> PayloadWriter<'a> {
    pub fn new(buf: &'a mut [MaybeUninit<u8>]) -> Self {
        Self { buf, pos: 0 }
    }

    /// Appends `data` followed by zero padding up to [`ALIGN`].
    pub fn put<T: bytemuck::Pod>(&mut self, data: &[T]) -> Result<(), SchemaError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let padded = section_len::<T>(data.len());
        let end = self.pos + padded;
        if end > self.buf.len() {
            return Err(SchemaError::LayoutMismatch {
                expected: end,
                actual: self.buf.len(),
            });
        }
        let dst = &mut self.buf[self.pos..self.pos + bytes.len()];
        // SAFETY: MaybeUninit<u8> has the layout of u8; lengths are equal.
        unsafe {
            std::ptr::copy_nonoverlapping(
                bytes.as_ptr(),
                dst.as_mut_ptr().cast::<u8>(),
                bytes.len(),
            )
        };
        for b in &mut self.buf[self.pos + bytes.len()..end] {
            b.write(0);
        }
        self.pos = end;
        Ok(())
    }

    /// Succeeds only when every byte of the payload has been written.
    pub fn finish(self) -> Result<(), SchemaError> {
        if self.pos != self.buf.len() {
            return Err(SchemaError::Incomplete {
                written: self.pos,
                len: self.buf.len(),
            });
        }
        Ok(())
    }
}

/// Views an initialised byte buffer as uninitialised (for encoding into a `Vec`).
pub fn as_uninit_mut(buf: &mut [u8]) -> &mut [MaybeUninit<u8>] {
    // SAFETY: u8 and MaybeUninit<u8> share layout; we only ever write through it.
    unsafe { std::slice::from_raw_parts_mut(buf.as_mut_ptr().cast(), buf.len()) }
}

/// Splits validated sections off the front of a received payload.
pub(crate) struct PayloadReader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> PayloadReader<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Result<Self, SchemaError> {
        if !(buf.as_ptr() as usize).is_multiple_of(ALIGN) && !buf.is_empty() {
            return Err(SchemaError::Alignment(ALIGN));
        }
        Ok(Self { buf, pos: 0 })
    }

    pub(crate) fn take<T: bytemuck::Pod>(&mut self, n: usize) -> Result<&'a [T], SchemaError> {
        let bytes = n * std::mem::size_of::<T>();
        let end = self.pos + section_len::<T>(n);
        if end > self.buf.len() {
            return Err(SchemaError::LayoutMismatch {
                expected: end,
                actual: self.buf.len(),
            });
        }
        let slice = &self.buf[self.pos..self.pos + bytes];
        self.pos = end;
        bytemuck::try_cast_slice(slice).map_err(|_| SchemaError::Alignment(ALIGN))
    }
}

/// Checks an image size from a header before any size arithmetic uses it.
pub(crate) fn check_dims(width: u32, height: u32) -> Result<usize, SchemaError> {
    if width == 0 || height == 0 || width > crate::MAX_IMAGE_SIDE || height > crate::MAX_IMAGE_SIDE
    {
        return Err(SchemaError::Dimensions { width, height });
    }
    Ok(width as usize * height as usize)
}

/// Checks a count from a header against a bound before it sizes anything.
pub(crate) fn check_count(what: &'static str, value: u32, max: u32) -> Result<usize, SchemaError> {
    if value > max {
        return Err(SchemaError::Count {
            what,
            value: value as u64,
        });
    }
    Ok(value as usize)
}

/// Checks that the whole payload matches the layout the header implies.
pub(crate) fn check_total(expected: usize, actual: usize) -> Result<(), SchemaError> {
    if expected != actual {
        return Err(SchemaError::LayoutMismatch { expected, actual });
    }
    Ok(())
}

/// Byte buffer aligned to [`ALIGN`], for encoding messages outside shared memory (tests, tools).
pub fn aligned_buffer(len: usize) -> Vec<u64> {
    vec![0u64; len.div_ceil(8)]
}
