//! Reads the scene's enums tagged by a `kind` key among the map's other keys (a furniture
//! piece, `robot.motion`) without serde's buffer. serde reads a `#[serde(tag = "kind")]`
//! enum into a buffer before it knows the variant, so `serde_path_to_error` cannot follow
//! into it and the YAML position is the map's start: `size: [1, "0.8m"]` was reported as
//! `furniture[0]` at the piece's `{`. Here `kind` is read first and the other keys are then
//! read straight from the YAML by the enum's externally tagged form (`{box: {...}}`), so an
//! error names `furniture[0].size[1]` and the value's own line and column.
//!
//! Keys written before `kind` are held as YAML values until the variant is known: a wrong
//! type in one of them names the key after the map (`furniture[0]: name: ...`), at the map's
//! position.

use std::fmt;
use std::marker::PhantomData;

use serde::Deserialize;
use serde::de::value::MapAccessDeserializer;
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, IntoDeserializer, MapAccess, VariantAccess,
    Visitor,
};
use serde_yaml_ng::Value;

/// The key naming the variant.
const TAG: &str = "kind";

/// An enum whose derived, externally tagged reading (`{variant: {keys}}`) is the tagged
/// form's: `deserialize_external` is serde's derive (`#[serde(remote = ...)]`).
pub(super) trait ExternallyTagged<'de>: Sized {
    fn deserialize_external<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error>;
}

/// Reads a map holding a `kind` key as the enum `T`; `expecting` says what a value that is
/// not a map should have been.
pub(super) fn deserialize<'de, D, T>(
    deserializer: D,
    expecting: &'static str,
) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: ExternallyTagged<'de>,
{
    deserializer.deserialize_map(TaggedVisitor {
        expecting,
        enum_type: PhantomData,
    })
}

struct TaggedVisitor<T> {
    expecting: &'static str,
    enum_type: PhantomData<T>,
}

impl<'de, T: ExternallyTagged<'de>> Visitor<'de> for TaggedVisitor<T> {
    type Value = T;

    fn expecting(&self, formatter: &mut fmt::Formatter) -> fmt::Result {
        formatter.write_str(self.expecting)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<T, A::Error> {
        let mut before_tag = Vec::new();
        loop {
            match map.next_key::<String>()? {
                Some(key) if key == TAG => break,
                Some(key) => {
                    let value = map.next_value::<Value>()?;
                    before_tag.push((key, value));
                }
                None => return Err(de::Error::missing_field(TAG)),
            }
        }
        T::deserialize_external(TagRead(Rest {
            held: before_tag.into_iter(),
            held_value: None,
            map,
        }))
    }
}

/// The map once its key `kind` is read: its value is the variant, the rest its keys.
struct TagRead<A>(Rest<A>);

/// The keys beside `kind`: those held from before it, then the map's own.
struct Rest<A> {
    held: std::vec::IntoIter<(String, Value)>,
    /// The value of the held key last handed out.
    held_value: Option<(String, Value)>,
    map: A,
}

impl<'de, A: MapAccess<'de>> Deserializer<'de> for TagRead<A> {
    type Error = A::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, A::Error> {
        visitor.visit_enum(self)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map struct enum
        identifier ignored_any
    }
}

impl<'de, A: MapAccess<'de>> EnumAccess<'de> for TagRead<A> {
    type Error = A::Error;
    type Variant = Rest<A>;

    fn variant_seed<V: DeserializeSeed<'de>>(
        self,
        seed: V,
    ) -> Result<(V::Value, Rest<A>), A::Error> {
        let TagRead(mut rest) = self;
        let variant = rest.map.next_value_seed(seed)?;
        Ok((variant, rest))
    }
}

impl<'de, A: MapAccess<'de>> VariantAccess<'de> for Rest<A> {
    type Error = A::Error;

    /// A variant without keys (`kind: static`) takes no other key.
    fn unit_variant(self) -> Result<(), A::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct NoKeys {}
        NoKeys::deserialize(MapAccessDeserializer::new(self)).map(|NoKeys {}| ())
    }

    fn newtype_variant_seed<S: DeserializeSeed<'de>>(self, seed: S) -> Result<S::Value, A::Error> {
        seed.deserialize(MapAccessDeserializer::new(self))
    }

    fn tuple_variant<V: Visitor<'de>>(self, _len: usize, visitor: V) -> Result<V::Value, A::Error> {
        Err(de::Error::invalid_type(de::Unexpected::Map, &visitor))
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, A::Error> {
        visitor.visit_map(self)
    }
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Rest<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, A::Error> {
        match self.held.next() {
            Some((key, value)) => {
                let read = seed.deserialize(IntoDeserializer::<A::Error>::into_deserializer(
                    key.as_str(),
                ))?;
                self.held_value = Some((key, value));
                Ok(Some(read))
            }
            None => self.map.next_key_seed(seed),
        }
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        match self.held_value.take() {
            Some((key, value)) => {
                let mut track = serde_path_to_error::Track::new();
                seed.deserialize(serde_path_to_error::Deserializer::new(value, &mut track))
                    .map_err(|e| {
                        let inner = match track.path().to_string() {
                            path if path == "." => String::new(),
                            path if path.starts_with('[') => path,
                            path => format!(".{path}"),
                        };
                        de::Error::custom(format_args!("{key}{inner}: {e}"))
                    })
            }
            None => self.map.next_value_seed(seed),
        }
    }
}
