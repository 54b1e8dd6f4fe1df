//! `[medium] ambient_index`: a number, or `"auto"` (the index a VDB grid's background maps
//! to). Left out, it is 1.0, except for VDB media, where it is `"auto"`: a cache's
//! background is the air around the plume, and the medium's box must not refract.

use std::fmt;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The ambient index as the scene gives it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum AmbientIndex {
    /// Not in the scene: 1.0, or `Auto` for VDB media.
    #[default]
    Unset,
    /// `"auto"`: the index the field's own data gives outside it (a VDB grid's background).
    Auto,
    /// A number.
    Value(f64),
}

impl AmbientIndex {
    /// The index when a value or `Unset` fixes it without the field's data: `Value(v)` is
    /// `v`; `Unset` is 1.0 unless `from_data_by_default` (VDB media), then `None`, as is
    /// `Auto`.
    pub fn fixed(self, from_data_by_default: bool) -> Option<f64> {
        match self {
            AmbientIndex::Value(v) => Some(v),
            AmbientIndex::Unset if !from_data_by_default => Some(1.0),
            AmbientIndex::Unset | AmbientIndex::Auto => None,
        }
    }

    /// True when the scene left the key out.
    pub fn is_unset(&self) -> bool {
        matches!(self, AmbientIndex::Unset)
    }
}

impl From<f64> for AmbientIndex {
    fn from(v: f64) -> Self {
        AmbientIndex::Value(v)
    }
}

impl Serialize for AmbientIndex {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            AmbientIndex::Value(v) => s.serialize_f64(*v),
            AmbientIndex::Auto => s.serialize_str("auto"),
            AmbientIndex::Unset => s.serialize_none(),
        }
    }
}

struct AmbientVisitor;

impl Visitor<'_> for AmbientVisitor {
    type Value = AmbientIndex;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a number or \"auto\"")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<AmbientIndex, E> {
        Ok(AmbientIndex::Value(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<AmbientIndex, E> {
        Ok(AmbientIndex::Value(v as f64))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<AmbientIndex, E> {
        Ok(AmbientIndex::Value(v as f64))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<AmbientIndex, E> {
        if v == "auto" {
            Ok(AmbientIndex::Auto)
        } else {
            Err(E::invalid_value(de::Unexpected::Str(v), &self))
        }
    }

    fn visit_none<E: de::Error>(self) -> Result<AmbientIndex, E> {
        Ok(AmbientIndex::Unset)
    }

    fn visit_unit<E: de::Error>(self) -> Result<AmbientIndex, E> {
        Ok(AmbientIndex::Unset)
    }
}

impl<'de> Deserialize<'de> for AmbientIndex {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(AmbientVisitor)
    }
}

impl crate::MediumSpec {
    /// The ambient index the scene fixes, or `None` where the field's data gives it
    /// (`"auto"`, and VDB media that leave the key out).
    pub fn ambient(&self) -> Option<f64> {
        let vdb = matches!(self.field, crate::FieldSpec::Vdb(_));
        self.ambient_index.fixed(vdb)
    }
}
