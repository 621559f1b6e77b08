//! Serde helpers for configuration fields that JSON cannot represent directly.

/// An `f32` where +∞ ("no limit") is written as `null` (JSON has no infinity) and `null` reads
/// back as +∞.
pub mod f32_infinite_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes +∞ as `null`, any other value as a number.
    pub fn serialize<S: Serializer>(value: &f32, serializer: S) -> Result<S::Ok, S::Error> {
        if *value == f32::INFINITY {
            serializer.serialize_none()
        } else {
            serializer.serialize_f32(*value)
        }
    }

    /// Reads `null` as +∞.
    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(deserializer)?.unwrap_or(f32::INFINITY))
    }
}
