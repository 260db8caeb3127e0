//! CDR, the wire format of a ROS 2 message as a bag stores it.
//!
//! A serialized message is a 4-byte encapsulation header followed by the message's fields
//! in OMG "plain" CDR (XCDR1): header byte 1 is 0 for big-endian, 1 for little-endian
//! (bytes 2..4 are options, ignored); each primitive is aligned to its own size counted
//! from the end of the header; a string is a u32 length (with its NUL) then the bytes; a
//! sequence a u32 count then the elements; a fixed array just the elements. The fields are
//! decoded with serde (`cdr-encoding`) into the structs of [`crate::ros_msgs`].

use byteorder::{BigEndian, LittleEndian};
use serde::de::{Deserialize, Deserializer, Visitor};
use serde::{Serialize, Serializer};

/// Encapsulation header of little-endian plain CDR (what ROS 2 writes on x86 and ARM).
const CDR_LE: [u8; 4] = [0, 1, 0, 0];

/// Decodes a serialized ROS 2 message (encapsulation header included); the error says why
/// it does not parse.
pub(crate) fn decode<'de, T: Deserialize<'de>>(bytes: &'de [u8]) -> Result<T, String> {
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(format!(
            "{} bytes, shorter than the 4-byte CDR encapsulation header",
            bytes.len()
        ));
    };
    let decoded = match (header[0], header[1]) {
        (0, 0) => cdr_encoding::from_bytes::<T, BigEndian>(body),
        (0, 1) => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        (a, b) => {
            return Err(format!(
                "CDR encapsulation {a:#04x}{b:02x} is not plain CDR (0x0000 big-endian or \
                 0x0001 little-endian)"
            ))
        }
    };
    decoded
        .map(|(value, _consumed)| value)
        .map_err(|e| format!("CDR does not parse: {e}"))
}

/// Serializes a message as little-endian plain CDR with its encapsulation header.
pub(crate) fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, String> {
    let body = cdr_encoding::to_vec::<T, LittleEndian>(message)
        .map_err(|e| format!("cannot serialize as CDR: {e}"))?;
    let mut out = Vec::with_capacity(4 + body.len());
    out.extend_from_slice(&CDR_LE);
    out.extend_from_slice(&body);
    Ok(out)
}

/// A `uint8[]` field, borrowed from the message bytes when decoding (an image is not copied)
/// and written as one block when encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Bytes<'a>(pub &'a [u8]);

impl Serialize for Bytes<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(self.0)
    }
}

impl<'de: 'a, 'a> Deserialize<'de> for Bytes<'a> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct BorrowedBytes<'a>(std::marker::PhantomData<&'a ()>);
        impl<'de: 'a, 'a> Visitor<'de> for BorrowedBytes<'a> {
            type Value = Bytes<'a>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a uint8[] sequence")
            }
            fn visit_borrowed_bytes<E>(self, v: &'de [u8]) -> Result<Self::Value, E> {
                Ok(Bytes(v))
            }
        }
        deserializer.deserialize_bytes(BorrowedBytes(std::marker::PhantomData))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, serde::Deserialize)]
    struct Sample<'a> {
        flag: u8,
        value: f64,
        name: String,
        #[serde(borrow)]
        data: Bytes<'a>,
        tail: [u32; 2],
    }

    #[test]
    fn round_trips_with_alignment() {
        let s = Sample {
            flag: 7,
            value: -2.5,
            name: "rgb8".into(),
            data: Bytes(&[1, 2, 3]),
            tail: [9, 10],
        };
        let bytes = encode(&s).expect("encode");
        // u8 at 0, f64 aligned to 8, string length at 16, "rgb8\0", data length at 28.
        assert_eq!(&bytes[..4], &CDR_LE);
        assert_eq!(bytes.len(), 4 + 8 + 8 + 4 + 5 + 3 + 4 + 3 + 1 + 8);
        assert_eq!(decode::<Sample>(&bytes), Ok(s));
    }

    #[test]
    fn reads_big_endian() {
        // u8 flag, 7 bytes padding, f64 1.0, string "", bytes [], tail [1, 2].
        let mut b = vec![0, 0, 0, 0, 5, 0, 0, 0, 0, 0, 0, 0];
        b.extend_from_slice(&1.0f64.to_be_bytes());
        b.extend_from_slice(&1u32.to_be_bytes());
        b.push(0);
        b.extend_from_slice(&[0, 0, 0]);
        b.extend_from_slice(&0u32.to_be_bytes());
        b.extend_from_slice(&1u32.to_be_bytes());
        b.extend_from_slice(&2u32.to_be_bytes());
        let s: Sample = decode(&b).expect("decode");
        assert_eq!((s.flag, s.value, s.tail), (5, 1.0, [1, 2]));
    }

    #[test]
    fn refuses_short_and_unknown_encapsulations() {
        assert!(decode::<Sample>(&[0, 1]).is_err());
        assert!(decode::<Sample>(&[0, 7, 0, 0, 1]).is_err());
        let bytes = encode(&Sample {
            flag: 1,
            value: 0.0,
            name: String::new(),
            data: Bytes(&[]),
            tail: [0, 0],
        })
        .expect("encode");
        for n in 4..bytes.len() {
            assert!(decode::<Sample>(&bytes[..n]).is_err(), "{n} bytes");
        }
    }
}
