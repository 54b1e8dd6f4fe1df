//! [`VdbError`]: why a VDB file could not be read or written.

/// Why a VDB file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum VdbError {
    #[error("{path}: no such file")]
    Missing { path: String },
    #[error("{path}: not a readable OpenVDB file: {message}")]
    Open { path: String, message: String },
    #[error("{path}: grid `{grid}` not found; available grids: {available}")]
    GridNotFound {
        path: String,
        grid: String,
        available: String,
    },
    #[error("{path}: grid `{grid}` has value type `{found}`, expected {expected}")]
    WrongType {
        path: String,
        grid: String,
        found: String,
        expected: &'static str,
    },
    #[error(
        "{path}: grid `{grid}`: a dense copy of the index box {min:?}..={max:?} needs {bytes} bytes, more than the memory cap of {cap} bytes"
    )]
    TooLarge {
        path: String,
        grid: String,
        min: [i32; 3],
        max: [i32; 3],
        bytes: u128,
        cap: u64,
    },
    #[error("{path}: grid `{grid}`: {message}")]
    Grid {
        path: String,
        grid: String,
        message: String,
    },
    #[error("{path}: cannot write: {message}")]
    Write { path: String, message: String },
    /// The shim or OpenVDB could not be loaded (the message says why and what to install).
    #[error("{message}")]
    Unavailable { message: String },
    #[error(
        "{path}: not enough memory to read grid `{grid}`: {bytes} bytes could not be allocated"
    )]
    Memory {
        path: String,
        grid: String,
        bytes: u64,
    },
}

impl VdbError {
    /// The message without the file's path (the checker's parent adds it back).
    pub(crate) fn reason(&self) -> String {
        match self {
            VdbError::Open { message, .. } => message.clone(),
            other => other.to_string(),
        }
    }
}
