//! Reading a scene file: TOML -> [`Scene`], then validation, with every error located
//! at file:line:column and named by its dotted key path.

use std::path::Path;

use crate::span::{Document, line_column};
use crate::validate::validate;
use crate::{Scene, SceneError, Shape};

/// Read and validate a scene file.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|err| SceneError::Io {
        path: path.to_owned(),
        err,
    })?;
    parse_scene(&text, path)
}

/// Parse and validate scene text; `path` is used in error messages.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene, SceneError> {
    let mut scene: Scene = toml::from_str(text).map_err(|e| {
        let doc = Document::parse(text);
        let mut offset = e.span().map_or(0, |s| s.start);
        let mut key = doc
            .key_at(offset)
            .unwrap_or_else(|| "(document)".to_owned());
        // serde reports unknown keys of buffered tables (internally tagged field kinds)
        // at the enclosing table: point at the unknown key itself when it is there.
        if let Some(name) = unknown_field(e.message()) {
            let child = format!("{key}.{name}");
            if let Some(span) = doc.exact_span_of(&child) {
                offset = span.start;
                key = child;
            }
        }
        let (line, column) = line_column(text, offset);
        SceneError::Parse {
            path: path.to_owned(),
            line,
            column,
            key,
            message: one_line(e.message()),
        }
    })?;
    validate(&scene).map_err(|p| {
        let offset = Document::parse(text).span_of(&p.key).map_or(0, |s| s.start);
        let (line, column) = line_column(text, offset);
        SceneError::Invalid {
            path: path.to_owned(),
            line,
            column,
            key: p.key,
            message: p.message,
        }
    })?;
    normalize(&mut scene);
    Ok(scene)
}

/// Unit plane normals (validated non-zero above).
fn normalize(scene: &mut Scene) {
    for o in &mut scene.objects {
        if let Shape::Plane { normal, .. } = &mut o.shape {
            let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
            for c in normal.iter_mut() {
                *c /= len;
            }
        }
    }
}

/// The key named by serde's "unknown field `name`, expected ..." message.
fn unknown_field(message: &str) -> Option<&str> {
    let rest = message.strip_prefix("unknown field `")?;
    rest.split('`').next()
}

/// Errors are one line on stderr.
fn one_line(message: &str) -> String {
    message.trim().replace('\n', "; ")
}

/// 1-based (line, column) of a dotted key path (`medium.field.n`, `object[2].shape`) in
/// scene text, for errors found after loading (e.g. by field builders) that should point
/// into the file. `None` if no part of the path is in the text.
pub fn locate_key(text: &str, key: &str) -> Option<(usize, usize)> {
    Document::parse(text)
        .span_of(key)
        .map(|span| line_column(text, span.start))
}
