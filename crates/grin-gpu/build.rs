//! Assembles every WGSL kernel in shaders/ (its `// #import` line names the shared files
//! it needs, concatenated in that order before it) and validates it with naga, so a
//! shader error breaks `cargo build`, not a run. The assembled sources go to OUT_DIR,
//! where `shaders.rs` includes them.

use std::path::{Path, PathBuf};

fn main() {
    let manifest =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let shader_dir = manifest.join("../../shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo::rerun-if-changed={}", shader_dir.display());
    println!(
        "cargo::rerun-if-changed={}",
        shader_dir.join("shared").display()
    );
    let mut kernels: Vec<PathBuf> = std::fs::read_dir(&shader_dir)
        .expect("read shaders/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "wgsl"))
        .collect();
    kernels.sort();
    let mut failures = Vec::new();
    for kernel in &kernels {
        println!("cargo::rerun-if-changed={}", kernel.display());
        match assemble(&shader_dir, kernel) {
            Ok(source) => {
                if let Err(e) = validate(kernel, &source) {
                    failures.push(e);
                }
                let name = kernel.file_name().expect("kernel has a file name");
                std::fs::write(out_dir.join(name), source)
                    .expect("write assembled shader to OUT_DIR");
            }
            Err(e) => failures.push(e),
        }
    }
    if !failures.is_empty() {
        for f in &failures {
            println!("cargo::warning={}", f.lines().next().unwrap_or(""));
        }
        panic!("WGSL validation failed:\n{}", failures.join("\n\n"));
    }
}

/// The kernel's shared imports (in order) followed by the kernel itself.
fn assemble(shader_dir: &Path, kernel: &Path) -> Result<String, String> {
    let text = std::fs::read_to_string(kernel).map_err(|e| format!("{}: {e}", kernel.display()))?;
    let mut source = String::new();
    if let Some(line) = text
        .lines()
        .find(|l| l.trim_start().starts_with("// #import"))
    {
        for import in line
            .trim_start()
            .trim_start_matches("// #import")
            .split_whitespace()
        {
            let path = shader_dir.join(import);
            println!("cargo::rerun-if-changed={}", path.display());
            let shared = std::fs::read_to_string(&path)
                .map_err(|e| format!("{}: import {import}: {e}", kernel.display()))?;
            source.push_str(&format!("// ---- {import} ----\n"));
            source.push_str(&shared);
            source.push('\n');
        }
    }
    source.push_str(&format!(
        "// ---- {} ----\n",
        kernel
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    ));
    source.push_str(&text);
    Ok(source)
}

fn validate(kernel: &Path, source: &str) -> Result<(), String> {
    let name = kernel.display().to_string();
    let module = naga::front::wgsl::parse_str(source).map_err(|e| {
        format!(
            "{name} (assembled): {}",
            e.emit_to_string_with_path(source, &name)
        )
    })?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&module)
    .map_err(|e| {
        format!(
            "{name} (assembled): {}",
            e.emit_to_string_with_path(source, &name)
        )
    })?;
    Ok(())
}
