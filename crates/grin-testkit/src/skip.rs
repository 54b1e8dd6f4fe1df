//! The one GPU-presence policy's words: a test (or the GPU half of one) that needs an
//! adapter and finds none says so loudly on stderr, never passes silently. Dependency-free,
//! so that grin-gpu's tests (which this crate depends on) can include it by path.

/// The running test's name: libtest names each test's thread after it.
pub fn test_name() -> String {
    std::thread::current()
        .name()
        .unwrap_or("<unnamed test>")
        .to_owned()
}

/// Print `SKIPPED (no GPU adapter): <test>` (and why there is none) on stderr.
pub fn skipped_no_gpu(test: &str, why: &str) {
    eprintln!("\nSKIPPED (no GPU adapter): {test}");
    if !why.is_empty() {
        eprintln!("  ({why})");
    }
}

/// Whether a missing adapter may skip a test that CI runs on lavapipe:
/// `GRIN_ALLOW_NO_GPU=1`. Without it, [`require_gpu`] fails the test.
pub fn no_gpu_allowed() -> bool {
    std::env::var("GRIN_ALLOW_NO_GPU").as_deref() == Ok("1")
}

/// For `test`, which must not pass without a GPU: `Ok(x)` (an adapter, a device) gives
/// `Some(x)`; an error fails the test, unless `GRIN_ALLOW_NO_GPU=1`, when it prints the
/// SKIPPED line and gives `None`.
pub fn require_gpu<T, E: std::fmt::Display>(test: &str, adapter: Result<T, E>) -> Option<T> {
    match adapter {
        Ok(x) => Some(x),
        Err(e) if no_gpu_allowed() => {
            skipped_no_gpu(test, &format!("{e}; GRIN_ALLOW_NO_GPU=1 is set"));
            None
        }
        Err(e) => panic!(
            "{test}: no GPU adapter: {e}\n(install mesa-vulkan-drivers for lavapipe, or set GRIN_ALLOW_NO_GPU=1 to skip loudly)"
        ),
    }
}

/// `test` found no GPU (`why`): a failure, unless `GRIN_ALLOW_NO_GPU=1`, when it prints
/// the SKIPPED line.
pub fn missing_gpu(test: &str, why: &str) {
    let _ = require_gpu::<(), _>(test, Err(why));
}
