//! Typed scene errors: every one names the file and, where known, the line, column and key.

use std::path::PathBuf;

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The io::Error is in the message only (as a `source()` too, `{:#}` printed it twice).
    #[error("{}: cannot read scene file: {}", path.display(), without_os_code(err))]
    Io { path: PathBuf, err: std::io::Error },
    /// TOML syntax or a value of the wrong shape (unknown key, unknown field kind, ...).
    #[error("{path}:{line}:{column}: {key}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        column: usize,
        key: String,
        message: String,
    },
    /// The TOML is well formed but a value is unusable (negative radius, n <= 0, ...).
    #[error("{path}:{line}:{column}: {key}: {message}")]
    Invalid {
        path: PathBuf,
        line: usize,
        column: usize,
        key: String,
        message: String,
    },
}

/// An io::Error's text without Rust's " (os error N)" suffix, for one-line messages.
fn without_os_code(e: &std::io::Error) -> String {
    let text = e.to_string();
    text.split(" (os error ").next().unwrap_or(&text).to_owned()
}
