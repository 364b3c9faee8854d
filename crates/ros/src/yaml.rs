//! YAML as rcl reads parameter files and `-p` values (`rcl_yaml_param_parser`, `get_value`):
//! an unquoted scalar is typed by its text, where the YAML 1.1 words `yes`, `on`, `off`, ...
//! are booleans, and a quoted scalar is always a string. serde_yaml_ng follows YAML 1.2, where
//! those words are strings, and its `Value` forgets whether a string was quoted: this tree
//! keeps what tells the two apart.

use std::borrow::Cow;
use std::fmt;

use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};

/// A YAML node; numbers and `true`/`false` typed by serde_yaml_ng, the other words as rcl
/// types them (see [`parse`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Yaml<'a> {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    /// Borrowed: serde_yaml_ng lent the characters out of the text; owned: it had to build
    /// them (escapes, joined lines), which a plain word never needs.
    Str(Cow<'a, str>),
    Seq(Vec<Yaml<'a>>),
    Map(Vec<(Yaml<'a>, Yaml<'a>)>),
}

/// Parses `text`, typing unquoted values as rcl does (mapping keys stay as written).
pub(crate) fn parse(text: &str) -> Result<Yaml<'_>, String> {
    let raw: Yaml = serde_yaml_ng::from_str(text).map_err(|e| e.to_string())?;
    Ok(raw.with_rcl_booleans(text))
}

/// rcl's booleans among unquoted scalars (`get_value` in rcl_yaml_param_parser's parse.c).
fn rcl_bool(word: &str) -> Option<bool> {
    match word {
        "y" | "Y" | "yes" | "Yes" | "YES" | "true" | "True" | "TRUE" | "on" | "On" | "ON" => {
            Some(true)
        }
        "n" | "N" | "no" | "No" | "NO" | "false" | "False" | "FALSE" | "off" | "Off" | "OFF" => {
            Some(false)
        }
        _ => None,
    }
}

/// Whether `s`, a string serde_yaml_ng lent out of `text`, was written without quotes and
/// without a `!!str` tag, which rcl honours as well (`!!str on`, the way to write the word as
/// a string) and serde_yaml_ng's `Value` forgets. It lends a scalar's characters where they
/// stand in the text, so a quoted scalar's characters are followed by its closing quote,
/// while a plain scalar never ends just before a quote (one written there would belong to
/// the scalar); a tag stands before the scalar, an anchor (`&a`) possibly between them.
fn is_plain(text: &str, s: &str) -> bool {
    let start = (s.as_ptr() as usize).wrapping_sub(text.as_ptr() as usize);
    let end = start.saturating_add(s.len());
    if end > text.len() || matches!(text.as_bytes().get(end), Some(b'\'' | b'"')) {
        return false;
    }
    let mut props = text[..start].trim_end();
    if let Some((before, anchor)) = props.rsplit_once(char::is_whitespace)
        && anchor.starts_with('&')
    {
        props = before.trim_end();
    }
    !["!!str", "!<tag:yaml.org,2002:str>"].iter().any(|tag| {
        props.strip_suffix(tag).is_some_and(|rest| {
            rest.is_empty() || rest.ends_with(|c: char| c.is_whitespace() || "[{,:-?".contains(c))
        })
    })
}

impl<'a> Yaml<'a> {
    fn with_rcl_booleans(self, text: &str) -> Self {
        match self {
            Self::Str(Cow::Borrowed(s)) if is_plain(text, s) => match rcl_bool(s) {
                Some(b) => Self::Bool(b),
                None => Self::Str(Cow::Borrowed(s)),
            },
            Self::Seq(items) => Self::Seq(
                items
                    .into_iter()
                    .map(|item| item.with_rcl_booleans(text))
                    .collect(),
            ),
            Self::Map(entries) => Self::Map(
                entries
                    .into_iter()
                    .map(|(key, value)| (key, value.with_rcl_booleans(text)))
                    .collect(),
            ),
            other => other,
        }
    }
}

impl<'de> Deserialize<'de> for Yaml<'de> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(YamlVisitor)
    }
}

struct YamlVisitor;

impl<'de> Visitor<'de> for YamlVisitor {
    type Value = Yaml<'de>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a YAML value")
    }

    fn visit_unit<E>(self) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Null)
    }

    /// An empty document.
    fn visit_none<E>(self) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Null)
    }

    fn visit_bool<E>(self, b: bool) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Bool(b))
    }

    fn visit_i64<E>(self, i: i64) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Int(i))
    }

    /// Beyond `i64` a double, as in rcl (where `strtol` overflows and `strtod` reads it).
    fn visit_u64<E>(self, u: u64) -> Result<Yaml<'de>, E> {
        Ok(i64::try_from(u).map_or(Yaml::Float(u as f64), Yaml::Int))
    }

    fn visit_f64<E>(self, f: f64) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Float(f))
    }

    fn visit_borrowed_str<E>(self, s: &'de str) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Str(Cow::Borrowed(s)))
    }

    fn visit_str<E>(self, s: &str) -> Result<Yaml<'de>, E> {
        Ok(Yaml::Str(Cow::Owned(s.to_string())))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Yaml<'de>, A::Error> {
        let mut items = Vec::new();
        while let Some(item) = seq.next_element()? {
            items.push(item);
        }
        Ok(Yaml::Seq(items))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Yaml<'de>, A::Error> {
        let mut entries = Vec::new();
        while let Some(entry) = map.next_entry()? {
            entries.push(entry);
        }
        Ok(Yaml::Map(entries))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn str(s: &str) -> Yaml<'_> {
        Yaml::Str(Cow::Borrowed(s))
    }

    #[test]
    fn unquoted_yaml_1_1_words_are_booleans_quoted_ones_strings() {
        for (text, want) in [
            ("yes", Yaml::Bool(true)),
            ("On", Yaml::Bool(true)),
            ("Y", Yaml::Bool(true)),
            ("off", Yaml::Bool(false)),
            ("NO", Yaml::Bool(false)),
            ("n", Yaml::Bool(false)),
            ("'yes'", str("yes")),
            ("\"off\"", str("off")),
            ("\"o\\x66f\"", str("off")),
            ("yess", str("yess")),
            ("oN", str("oN")),
        ] {
            assert_eq!(parse(text).unwrap(), want, "{text}");
        }
        assert_eq!(
            parse("[on, 'off', \"no\", n]").unwrap(),
            Yaml::Seq(vec![
                Yaml::Bool(true),
                str("off"),
                str("no"),
                Yaml::Bool(false)
            ])
        );
        // Keys stay as written; values in block and flow mappings are typed.
        assert_eq!(
            parse("yes: off\nb: {c: 'on', d: on}\n").unwrap(),
            Yaml::Map(vec![
                (str("yes"), Yaml::Bool(false)),
                (
                    str("b"),
                    Yaml::Map(vec![(str("c"), str("on")), (str("d"), Yaml::Bool(true))])
                ),
            ])
        );
    }

    /// rcl keeps a `!!str` scalar a string; `!!str on` used to be the bool true.
    #[test]
    fn a_str_tag_keeps_the_words_strings() {
        for text in [
            "!!str on",
            "!!str  yes",
            "!<tag:yaml.org,2002:str> off",
            "&a !!str n",
            "!!str &a Y",
        ] {
            let word = text.rsplit(' ').next().unwrap();
            assert_eq!(parse(text).unwrap(), str(word), "{text}");
        }
        assert_eq!(
            parse("a: !!str yes\nb: [!!str no, no]\nc: x!!str on\n").unwrap(),
            Yaml::Map(vec![
                (str("a"), str("yes")),
                (str("b"), Yaml::Seq(vec![str("no"), Yaml::Bool(false)])),
                (str("c"), str("x!!str on")),
            ])
        );
    }

    /// Wide spaces (a no-break space pasted from a web page) before a plain scalar used to
    /// panic: the text after the last space was cut inside the space's bytes.
    #[test]
    fn multibyte_spaces_before_a_word_are_read_not_a_panic() {
        assert_eq!(
            parse("[a\u{a0}b, on]").unwrap(),
            Yaml::Seq(vec![str("a\u{a0}b"), Yaml::Bool(true)])
        );
        assert_eq!(
            parse("k\u{3000}x: on").unwrap(),
            Yaml::Map(vec![(str("k\u{3000}x"), Yaml::Bool(true))])
        );
    }

    #[test]
    fn numbers_and_empty_values() {
        assert_eq!(parse("3").unwrap(), Yaml::Int(3));
        assert_eq!(parse("-0x10").unwrap(), Yaml::Int(-16));
        assert_eq!(parse("3.5").unwrap(), Yaml::Float(3.5));
        assert_eq!(parse("1e3").unwrap(), Yaml::Float(1000.0));
        assert_eq!(parse("-.inf").unwrap(), Yaml::Float(f64::NEG_INFINITY));
        assert_eq!(
            parse("18446744073709551615").unwrap(),
            Yaml::Float(u64::MAX as f64)
        );
        assert_eq!(parse("'3'").unwrap(), str("3"));
        assert_eq!(parse("").unwrap(), Yaml::Null);
        assert_eq!(parse("~").unwrap(), Yaml::Null);
    }
}
