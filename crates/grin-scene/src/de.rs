//! A serde deserializer over a parsed TOML table that knows where it is: every error
//! carries the key path it happened at (`object[1].shape.sphere.radius`) and unknown
//! keys arrive as a typed error (serde's `Error::unknown_field`, with the key and the
//! keys expected), so the loader points at the key itself without reading either out of
//! a message's text. Internally tagged tables (`field = { kind = ..., ... }`) are
//! buffered by serde and checked after this deserializer has returned from them; their
//! unknown keys come back typed all the same, at the tagged table's path.

use std::fmt;

use serde::de::{self, DeserializeSeed, IntoDeserializer, Visitor};
use toml::{Table, Value};

use crate::span::Segment;

/// What went wrong, and at which key path.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DeError {
    /// From the document's root to the value that failed.
    pub path: Vec<Segment>,
    pub kind: DeErrorKind,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum DeErrorKind {
    /// A key the table's type does not have.
    UnknownField {
        field: String,
        expected: &'static [&'static str],
    },
    /// Anything else, in serde's words (wrong type, unknown variant, missing key, ...).
    Other(String),
}

impl DeError {
    fn at(mut self, segment: Segment) -> Self {
        self.path.insert(0, segment);
        self
    }

    /// The dotted key path of the failing key: for an unknown key, the key itself.
    pub(crate) fn key(&self) -> String {
        let mut path = self.path.clone();
        if let DeErrorKind::UnknownField { field, .. } = &self.kind {
            path.push(Segment::Key(field.clone()));
        }
        display_path(&path)
    }
}

/// `a.b[2].c`.
fn display_path(path: &[Segment]) -> String {
    let mut out = String::new();
    for seg in path {
        match seg {
            Segment::Key(k) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(k);
            }
            Segment::Index(i) => out.push_str(&format!("[{i}]")),
        }
    }
    out
}

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.kind {
            DeErrorKind::UnknownField { field, expected } => {
                write!(f, "unknown field `{field}`, ")?;
                let quoted: Vec<String> = expected.iter().map(|e| format!("`{e}`")).collect();
                match quoted.as_slice() {
                    [] => write!(f, "there are no fields"),
                    [one] => write!(f, "expected {one}"),
                    [a, b] => write!(f, "expected {a} or {b}"),
                    many => write!(f, "expected one of {}", many.join(", ")),
                }
            }
            DeErrorKind::Other(message) => f.write_str(message),
        }
    }
}

impl std::error::Error for DeError {}

impl de::Error for DeError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        DeError {
            path: Vec::new(),
            kind: DeErrorKind::Other(msg.to_string()),
        }
    }

    fn unknown_field(field: &str, expected: &'static [&'static str]) -> Self {
        DeError {
            path: Vec::new(),
            kind: DeErrorKind::UnknownField {
                field: field.to_owned(),
                expected,
            },
        }
    }
}

/// Deserialize `T` from a parsed document.
pub(crate) fn from_table<T: de::DeserializeOwned>(table: Table) -> Result<T, DeError> {
    T::deserialize(ValueDe(Value::Table(table)))
}

struct ValueDe(Value);

impl<'de> de::Deserializer<'de> for ValueDe {
    type Error = DeError;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.0 {
            Value::String(s) => visitor.visit_string(s),
            Value::Integer(i) => visitor.visit_i64(i),
            Value::Float(x) => visitor.visit_f64(x),
            Value::Boolean(b) => visitor.visit_bool(b),
            Value::Datetime(d) => visitor.visit_string(d.to_string()),
            Value::Array(a) => visitor.visit_seq(SeqDe {
                items: a.into_iter().enumerate(),
            }),
            Value::Table(t) => visitor.visit_map(MapDe {
                entries: t.into_iter(),
                value: None,
            }),
        }
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        // TOML has no null: a present key is Some.
        visitor.visit_some(self)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, DeError> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        match self.0 {
            // A unit variant by name: `integrator = "sharma"`.
            Value::String(s) => visitor.visit_enum(s.into_deserializer()),
            // `shape = { sphere = { ... } }`: one key, the variant.
            Value::Table(t) if t.len() == 1 => {
                let (variant, value) = t.into_iter().next().expect("one entry");
                visitor.visit_enum(EnumDe { variant, value })
            }
            Value::Table(t) => Err(de::Error::custom(format!(
                "expected a table with exactly one key (the variant), got {} keys",
                t.len()
            ))),
            other => Err(de::Error::invalid_type(unexpected(&other), &visitor)),
        }
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf unit unit_struct seq tuple tuple_struct map struct
        identifier ignored_any
    }
}

fn unexpected(v: &Value) -> de::Unexpected<'_> {
    match v {
        Value::String(s) => de::Unexpected::Str(s),
        Value::Integer(i) => de::Unexpected::Signed(*i),
        Value::Float(x) => de::Unexpected::Float(*x),
        Value::Boolean(b) => de::Unexpected::Bool(*b),
        Value::Datetime(_) => de::Unexpected::Other("a datetime"),
        Value::Array(_) => de::Unexpected::Seq,
        Value::Table(_) => de::Unexpected::Map,
    }
}

struct SeqDe {
    items: std::iter::Enumerate<std::vec::IntoIter<Value>>,
}

impl<'de> de::SeqAccess<'de> for SeqDe {
    type Error = DeError;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, DeError> {
        match self.items.next() {
            Some((i, v)) => seed
                .deserialize(ValueDe(v))
                .map(Some)
                .map_err(|e| e.at(Segment::Index(i))),
            None => Ok(None),
        }
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.items.len())
    }
}

struct MapDe {
    entries: toml::map::IntoIter<String, Value>,
    /// The value of the key just read, with the key (for the path).
    value: Option<(String, Value)>,
}

impl<'de> de::MapAccess<'de> for MapDe {
    type Error = DeError;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, DeError> {
        let Some((key, value)) = self.entries.next() else {
            return Ok(None);
        };
        // An unknown key fails here, typed (DeErrorKind::UnknownField names it); the
        // path is this table's, added by the caller.
        let k = seed.deserialize(key.clone().into_deserializer())?;
        self.value = Some((key, value));
        Ok(Some(k))
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, DeError> {
        let (key, value) = self
            .value
            .take()
            .ok_or_else(|| de::Error::custom("a value was asked for before its key"))?;
        seed.deserialize(ValueDe(value))
            .map_err(|e| e.at(Segment::Key(key)))
    }
}

struct EnumDe {
    variant: String,
    value: Value,
}

impl<'de> de::EnumAccess<'de> for EnumDe {
    type Error = DeError;
    type Variant = VariantDe;

    fn variant_seed<V: DeserializeSeed<'de>>(
        self,
        seed: V,
    ) -> Result<(V::Value, VariantDe), DeError> {
        let v = seed.deserialize(self.variant.clone().into_deserializer())?;
        Ok((
            v,
            VariantDe {
                variant: self.variant,
                value: self.value,
            },
        ))
    }
}

struct VariantDe {
    variant: String,
    value: Value,
}

impl VariantDe {
    fn within<T>(self, f: impl FnOnce(ValueDe) -> Result<T, DeError>) -> Result<T, DeError> {
        let key = Segment::Key(self.variant);
        f(ValueDe(self.value)).map_err(|e| e.at(key))
    }
}

impl<'de> de::VariantAccess<'de> for VariantDe {
    type Error = DeError;

    fn unit_variant(self) -> Result<(), DeError> {
        self.within(de::Deserialize::deserialize)
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, DeError> {
        self.within(|d| seed.deserialize(d))
    }

    fn tuple_variant<V: Visitor<'de>>(self, _len: usize, visitor: V) -> Result<V::Value, DeError> {
        self.within(|d| de::Deserializer::deserialize_seq(d, visitor))
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        self.within(|d| de::Deserializer::deserialize_map(d, visitor))
    }
}
