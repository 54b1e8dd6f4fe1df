//! Reading a scene file: TOML -> [`Scene`], then validation.

use std::path::Path;

use crate::{Scene, SceneError};

/// Read and validate a scene file.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_scene(&text, path)
}

/// Parse and validate scene text; `path` is used in error messages.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene, SceneError> {
    let scene: Scene = toml::from_str(text).map_err(|e| {
        let (line, column) = e
            .span()
            .map(|s| line_column(text, s.start))
            .unwrap_or((0, 0));
        SceneError::Parse {
            path: path.to_owned(),
            line,
            column,
            key: String::new(),
            message: e.message().to_owned(),
        }
    })?;
    Ok(scene)
}

/// 1-based line and column of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}
