//! Helpers the end-to-end tests share: the `grin` binary, its outcome, the GPU's
//! presence and an EXR's channels.

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};

/// The `grin` binary built with these tests.
pub fn grin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_grin"))
}

/// Fail with both streams when `grin` did.
pub fn assert_ok(out: &Output) {
    assert!(
        out.status.success(),
        "stdout {}\nstderr {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Whether a GPU adapter (lavapipe in CI) is there.
pub fn gpu_available() -> bool {
    grin_gpu::GpuContext::new_headless().is_ok()
}

/// Every channel of an EXR's first layer by name, and the layer's width.
pub fn exr_channels(path: &Path) -> (usize, HashMap<String, Vec<f64>>) {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).expect("read exr");
    let layer = &image.layer_data[0];
    let map = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().map(f64::from).collect(),
            )
        })
        .collect();
    (layer.size.width(), map)
}
