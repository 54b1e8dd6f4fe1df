//! Where a key sits in the scene text: dotted key paths (`object[2].shape.sphere.radius`)
//! resolved against toml's spanned document tree to a 1-based line and column.

use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// One step of a key path: a table key or an array index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Segment {
    Key(String),
    Index(usize),
}

/// Split `a.b[2].c` into segments.
pub(crate) fn parse_path(path: &str) -> Vec<Segment> {
    let mut out = Vec::new();
    for part in path.split('.') {
        let mut rest = part;
        if let Some(i) = rest.find('[') {
            if i > 0 {
                out.push(Segment::Key(rest[..i].to_owned()));
            }
            rest = &rest[i..];
            while let Some(stripped) = rest.strip_prefix('[') {
                let Some(end) = stripped.find(']') else { break };
                if let Ok(n) = stripped[..end].parse() {
                    out.push(Segment::Index(n));
                }
                rest = &stripped[end + 1..];
            }
        } else if !rest.is_empty() {
            out.push(Segment::Key(rest.to_owned()));
        }
    }
    out
}

/// The spanned document, if the text parses (it does whenever validation runs).
pub(crate) struct Document<'i> {
    root: Option<Spanned<DeTable<'i>>>,
}

impl<'i> Document<'i> {
    pub(crate) fn parse(text: &'i str) -> Self {
        Document {
            root: DeTable::parse(text).ok(),
        }
    }

    /// Byte span of the deepest part of `path` present in the document: the key itself
    /// for a table entry, the element for an array index. `None` if not even the first
    /// segment is present.
    pub(crate) fn span_of(&self, path: &str) -> Option<Range<usize>> {
        self.resolve(path).map(|(span, _)| span)
    }

    /// Byte span of exactly `path` (its key, or element), if all of it is present.
    pub(crate) fn exact_span_of(&self, path: &str) -> Option<Range<usize>> {
        self.resolve(path)
            .and_then(|(span, complete)| complete.then_some(span))
    }

    /// Byte span of the value at exactly `path`, if all of it is present.
    pub(crate) fn value_span_of(&self, path: &str) -> Option<Range<usize>> {
        let (_, value, complete) = self.resolve_both(path)?;
        complete.then_some(value)
    }

    /// The span of the deepest present part of `path` and whether that is all of it.
    fn resolve(&self, path: &str) -> Option<(Range<usize>, bool)> {
        self.resolve_both(path)
            .map(|(key, _, complete)| (key, complete))
    }

    /// The key span and value span of the deepest present part of `path`, and whether
    /// that is all of it.
    fn resolve_both(&self, path: &str) -> Option<(Range<usize>, Range<usize>, bool)> {
        let root = self.root.as_ref()?;
        let segments = parse_path(path);
        let wanted = segments.len();
        let mut found = 0;
        let mut table: Option<&DeTable<'i>> = Some(root.get_ref());
        let mut value: Option<&DeValue<'i>> = None;
        let mut best = None;
        for seg in segments {
            let next = match (&seg, table, value) {
                (Segment::Key(k), Some(t), _) => t
                    .iter()
                    .find(|(key, _)| key.get_ref().as_ref() == k.as_str())
                    .map(|(key, v)| (key.span(), v)),
                (Segment::Index(i), _, Some(DeValue::Array(a))) => a.get(*i).map(|v| (v.span(), v)),
                _ => None,
            };
            let Some((span, v)) = next else { break };
            best = Some((span, v.span()));
            found += 1;
            value = Some(v.get_ref());
            table = v.get_ref().as_table();
        }
        best.map(|(key, value)| (key, value, found == wanted))
    }

    /// The dotted path of the deepest key whose key or value span contains byte `offset`.
    pub(crate) fn key_at(&self, offset: usize) -> Option<String> {
        key_in_table(self.root.as_ref()?.get_ref(), offset)
    }
}

/// Deepest key path in `t` around `offset`. Tables' own spans do not always cover their
/// bodies (`[camera]` headers), so every entry is searched.
fn key_in_table(t: &DeTable<'_>, offset: usize) -> Option<String> {
    for (k, v) in t.iter() {
        if let Some(inner) = key_in_value(v.get_ref(), offset) {
            return Some(format!("{}{inner}", k.get_ref()));
        }
        if k.span().contains(&offset) || v.span().contains(&offset) {
            return Some(k.get_ref().to_string());
        }
    }
    None
}

/// The path below a value (starting with `.` or `[`) that contains `offset`.
fn key_in_value(v: &DeValue<'_>, offset: usize) -> Option<String> {
    match v {
        DeValue::Table(t) => key_in_table(t, offset).map(|p| format!(".{p}")),
        DeValue::Array(a) => a.iter().enumerate().find_map(|(i, e)| {
            key_in_value(e.get_ref(), offset)
                .or_else(|| e.span().contains(&offset).then(String::new))
                .map(|p| format!("[{i}]{p}"))
        }),
        _ => None,
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_split_into_keys_and_indices() {
        assert_eq!(
            parse_path("object[2].shape.sphere.radius"),
            vec![
                Segment::Key("object".into()),
                Segment::Index(2),
                Segment::Key("shape".into()),
                Segment::Key("sphere".into()),
                Segment::Key("radius".into()),
            ]
        );
        assert_eq!(parse_path("medium.field.plumes[0].s").len(), 5);
    }

    #[test]
    fn spans_point_at_keys_including_array_tables() {
        let text = "[camera]\nfov_y_deg = 10.0\n\n[[object]]\nshape = 1\n\n[[object]]\nshape = { sphere = { center = [0, 0, 0], radius = -1.0 } }\n";
        let doc = Document::parse(text);
        let span = doc
            .span_of("object[1].shape.sphere.radius")
            .expect("present");
        assert_eq!(&text[span.clone()], "radius");
        assert_eq!(line_column(text, span.start), (8, 42));
        // A missing tail resolves to the deepest existing key.
        let span = doc.span_of("camera.up").expect("camera present");
        assert_eq!(&text[span], "camera");
        assert_eq!(
            doc.key_at(text.find("-1.0").expect("in text")),
            Some("object[1].shape.sphere.radius".into())
        );
    }
}
