//! A bounded reader for plain CDR (XCDR1, what rosbag2 MCAP files hold) into the serde structs
//! of [`super::ros2`], and for the ROS 1 serialisation ([`from_ros1_bytes`], the structs of
//! [`super::ros1`]): the same wire elements without the encapsulation header, without alignment
//! padding, always little-endian, and with strings that carry no terminating NUL.
//!
//! The `cdr` crate's reader allocates and zero-fills every string or byte sequence at its
//! *declared* length before reading it, so a 20-byte message declaring a 4 GiB `frame_id` made
//! it allocate 4 GiB (found by fuzzing, fuzz/README.md). This reader reads from the message
//! slice and checks every declared length against the bytes that remain before allocating;
//! the wire format is the same (the crate still writes fixtures).

use std::fmt;

use serde::de::{self, DeserializeSeed, IntoDeserializer, SeqAccess, Visitor};

/// Bytes of the encapsulation header (`00 00` big-endian / `00 01` little-endian, 2 option bytes).
const ENCAPSULATION_HEADER_BYTES: usize = 4;

/// A decode error with its message.
#[derive(Debug)]
pub(crate) struct CdrError(String);

impl fmt::Display for CdrError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for CdrError {}

impl de::Error for CdrError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Self(msg.to_string())
    }
}

type Result<T> = std::result::Result<T, CdrError>;

/// Deserializes one CDR message (encapsulation header included).
pub(crate) fn from_bytes<T: de::DeserializeOwned>(data: &[u8]) -> Result<T> {
    let Some((header, body)) = data.split_at_checked(ENCAPSULATION_HEADER_BYTES) else {
        return Err(CdrError(format!(
            "message of {} bytes is shorter than the {ENCAPSULATION_HEADER_BYTES}-byte encapsulation header",
            data.len()
        )));
    };
    // Representation identifiers CDR_BE/CDR_LE (0, 1) and PL_CDR_BE/PL_CDR_LE (2, 3), read the
    // same way as the `cdr` crate does.
    let little_endian = match (header[0], header[1]) {
        (0, 0 | 2) => false,
        (0, 1 | 3) => true,
        (a, b) => {
            return Err(CdrError(format!(
                "expected encapsulation 00 00 (big-endian) or 00 01 (little-endian), found {a:02x} {b:02x}"
            )))
        }
    };
    let mut reader = Reader {
        data: body,
        pos: 0,
        little_endian,
        dialect: Dialect::Cdr,
    };
    T::deserialize(&mut reader)
}

/// Deserializes one ROS 1 message (`ros1msg` schemas, `ros1` message encoding).
pub(crate) fn from_ros1_bytes<T: de::DeserializeOwned>(data: &[u8]) -> Result<T> {
    let mut reader = Reader {
        data,
        pos: 0,
        little_endian: true,
        dialect: Dialect::Ros1,
    };
    let value = T::deserialize(&mut reader)?;
    // ROS 1 messages have no padding: bytes left over mean another message type.
    if reader.pos != data.len() {
        return Err(CdrError(format!(
            "{} bytes left after the message's last field (of {})",
            data.len() - reader.pos,
            data.len()
        )));
    }
    Ok(value)
}

/// The two wire formats read by [`Reader`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dialect {
    /// XCDR1: aligned primitives, NUL-terminated strings.
    Cdr,
    /// ROS 1: packed primitives, strings without NUL.
    Ros1,
}

struct Reader<'a> {
    data: &'a [u8],
    /// Offset into `data` (alignment is relative to the end of the encapsulation header).
    pos: usize,
    little_endian: bool,
    dialect: Dialect,
}

impl<'a> Reader<'a> {
    /// Bytes before `data` in the message (for offsets in error messages).
    fn header_bytes(&self) -> usize {
        match self.dialect {
            Dialect::Cdr => ENCAPSULATION_HEADER_BYTES,
            Dialect::Ros1 => 0,
        }
    }

    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(CdrError(format!(
                "{what} needs {n} bytes at offset {}, but only {} remain",
                self.pos + self.header_bytes(),
                self.remaining()
            )));
        }
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    /// Reads an `N`-byte primitive aligned to `N`.
    fn primitive<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        if self.dialect == Dialect::Cdr {
            let padding = (N - self.pos % N) % N;
            self.take(padding, "alignment padding")?;
        }
        let mut bytes = [0u8; N];
        bytes.copy_from_slice(self.take(N, what)?);
        if self.little_endian != cfg!(target_endian = "little") {
            bytes.reverse();
        }
        Ok(bytes)
    }

    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_ne_bytes(self.primitive(what)?))
    }

    /// A `u32` length followed by that many bytes, checked before anything is allocated.
    fn sequence_bytes(&mut self, what: &str) -> Result<&'a [u8]> {
        let len = self.u32(what)? as usize;
        self.take(len, what)
    }

    fn string(&mut self) -> Result<String> {
        let bytes = self.sequence_bytes("string")?;
        // The CDR length counts the terminating NUL, which is dropped (as the `cdr` crate
        // does); ROS 1 strings have none.
        let text = match self.dialect {
            Dialect::Cdr => bytes.strip_suffix(&[0]).unwrap_or(bytes),
            Dialect::Ros1 => bytes,
        };
        String::from_utf8(text.to_vec()).map_err(|e| CdrError(format!("string is not UTF-8: {e}")))
    }
}

struct Elements<'r, 'a> {
    reader: &'r mut Reader<'a>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_, '_> {
    type Error = CdrError;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.reader).map(Some)
    }

    fn size_hint(&self) -> Option<usize> {
        // Every element takes at least one byte: never promise more than remain.
        Some(self.left.min(self.reader.remaining()))
    }
}

macro_rules! primitive {
    ($method:ident, $visit:ident, $ty:ty) => {
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
            let v = <$ty>::from_ne_bytes(self.primitive(stringify!($ty))?);
            visitor.$visit(v)
        }
    };
}

impl<'de> de::Deserializer<'de> for &mut Reader<'_> {
    type Error = CdrError;

    primitive!(deserialize_u8, visit_u8, u8);
    primitive!(deserialize_u16, visit_u16, u16);
    primitive!(deserialize_u32, visit_u32, u32);
    primitive!(deserialize_u64, visit_u64, u64);
    primitive!(deserialize_i8, visit_i8, i8);
    primitive!(deserialize_i16, visit_i16, i16);
    primitive!(deserialize_i32, visit_i32, i32);
    primitive!(deserialize_i64, visit_i64, i64);
    primitive!(deserialize_f32, visit_f32, f32);
    primitive!(deserialize_f64, visit_f64, f64);

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value> {
        Err(CdrError("CDR is not self-describing".into()))
    }

    fn deserialize_bool<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        match self.primitive::<1>("bool")?[0] {
            0 => visitor.visit_bool(false),
            1 => visitor.visit_bool(true),
            v => Err(CdrError(format!("expected a bool (0 or 1), found {v}"))),
        }
    }

    fn deserialize_char<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_char(char::from(self.primitive::<1>("char")?[0]))
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_string(self.string()?)
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_string(self.string()?)
    }

    fn deserialize_bytes<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_byte_buf(self.sequence_bytes("byte sequence")?.to_vec())
    }

    fn deserialize_byte_buf<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_byte_buf(self.sequence_bytes("byte sequence")?.to_vec())
    }

    fn deserialize_option<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value> {
        Err(CdrError("optional fields are not plain CDR".into()))
    }

    fn deserialize_unit<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        visitor.visit_unit()
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(self, _name: &'static str, visitor: V) -> Result<V::Value> {
        visitor.visit_unit()
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value> {
        let len = self.u32("sequence length")? as usize;
        self.deserialize_tuple(len, visitor)
    }

    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value> {
        visitor.visit_seq(Elements {
            reader: self,
            left: len,
        })
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value> {
        self.deserialize_tuple(len, visitor)
    }

    fn deserialize_map<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value> {
        Err(CdrError("maps are not plain CDR".into()))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value> {
        self.deserialize_tuple(fields.len(), visitor)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value> {
        visitor.visit_enum(self)
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value> {
        Err(CdrError("identifiers are not plain CDR".into()))
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value> {
        Err(CdrError("cannot skip a field of unknown type in CDR".into()))
    }

    fn is_human_readable(&self) -> bool {
        false
    }
}

impl<'de> de::EnumAccess<'de> for &mut Reader<'_> {
    type Error = CdrError;
    type Variant = Self;

    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, Self)> {
        let index = self.u32("enum discriminant")?;
        let value = seed.deserialize(index.into_deserializer())?;
        Ok((value, self))
    }
}

impl<'de> de::VariantAccess<'de> for &mut Reader<'_> {
    type Error = CdrError;

    fn unit_variant(self) -> Result<()> {
        Ok(())
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value> {
        seed.deserialize(self)
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value> {
        de::Deserializer::deserialize_tuple(self, len, visitor)
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value> {
        de::Deserializer::deserialize_tuple(self, fields.len(), visitor)
    }
}

#[cfg(test)]
mod tests {
    use super::super::ros2;
    use super::*;

    fn camera_info() -> ros2::CameraInfo {
        ros2::CameraInfo {
            header: ros2::Header {
                stamp: ros2::Time {
                    sec: 1_311_868_164,
                    nanosec: 363_181_000,
                },
                frame_id: "camera_optical".into(),
            },
            height: 480,
            width: 640,
            distortion_model: "plumb_bob".into(),
            d: vec![0.1, -0.2, 0.0, 0.0, 0.05],
            k: [520.9, 0.0, 325.1, 0.0, 521.0, 249.7, 0.0, 0.0, 1.0],
            roi: ros2::RegionOfInterest {
                do_rectify: true,
                ..Default::default()
            },
            ..Default::default()
        }
    }

    #[test]
    fn reads_what_the_cdr_crate_writes_in_both_byte_orders() {
        let info = camera_info();
        let image = ros2::Image {
            header: info.header.clone(),
            height: 1,
            width: 3,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: 3,
            data: vec![1, 2, 3],
        };
        let le = cdr::serialize::<_, _, cdr::CdrLe>(&info, cdr::Infinite).unwrap();
        let be = cdr::serialize::<_, _, cdr::CdrBe>(&info, cdr::Infinite).unwrap();
        assert_eq!(from_bytes::<ros2::CameraInfo>(&le).unwrap(), info);
        assert_eq!(from_bytes::<ros2::CameraInfo>(&be).unwrap(), info);
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&image, cdr::Infinite).unwrap();
        assert_eq!(from_bytes::<ros2::Image>(&bytes).unwrap(), image);
    }

    #[test]
    fn declared_lengths_beyond_the_message_fail_without_allocating() {
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(&camera_info(), cdr::Infinite).unwrap();
        // The frame_id length sits after the encapsulation header and the 8-byte stamp.
        let mut huge = bytes.clone();
        huge[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        let err = from_bytes::<ros2::CameraInfo>(&huge).unwrap_err().to_string();
        assert!(err.contains("4294967295 bytes"), "{err}");
        for len in 0..bytes.len() {
            assert!(
                from_bytes::<ros2::CameraInfo>(&bytes[..len]).is_err(),
                "prefix {len}"
            );
        }
    }
}
