//! [`GpuError`]: every way the GPU path can fail, each with a one-line reason.

/// Why the GPU could not render.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter matched (no Vulkan driver, or `WGPU_BACKEND` / `WGPU_ADAPTER_NAME`
    /// excluded every adapter).
    #[error(
        "no GPU adapter found{filter}; install a Vulkan driver (e.g. mesa-vulkan-drivers for lavapipe) or change WGPU_BACKEND / WGPU_ADAPTER_NAME (adapters seen: {seen})"
    )]
    NoAdapter { filter: String, seen: String },
    #[error("GPU device request failed on {adapter}: {message}")]
    Device { adapter: String, message: String },
    /// A resource would exceed the adapter's limits (checked before creating it).
    #[error("{what} needs {needed} but the adapter {adapter} allows at most {limit}")]
    TooLarge {
        what: String,
        needed: String,
        limit: String,
        adapter: String,
    },
    /// wgpu reported an out-of-memory error.
    #[error("GPU out of memory while {during}: {message}")]
    OutOfMemory { during: String, message: String },
    /// wgpu validation or internal error (a bug in grin if it happens).
    #[error("GPU error while {during}: {message}")]
    Wgpu { during: String, message: String },
    #[error("GPU device lost: {0}")]
    DeviceLost(String),
    /// The scene uses something the GPU marcher does not do yet.
    #[error("the GPU backend does not support {0} yet; use --backend cpu")]
    Unsupported(String),
    #[error("{0}")]
    Memory(String),
    #[error("GPU render not ready: {0}")]
    NotReady(String),
    #[error("render cancelled")]
    Cancelled,
    #[error("baking the field for the GPU: {0}")]
    Bake(String),
}
