//! One module per subcommand.

pub mod bake;
pub mod bench;
pub mod dataset;
pub mod export;
pub mod info;
pub mod info_vdb;
pub mod render;
pub mod trace;
pub mod view;

use indicatif::{ProgressBar, ProgressStyle};

/// Declare the scene file and the files it reads (at its frame) inputs while the guard
/// lives: no output may replace one ([`grin_output::protect_inputs`]).
pub fn protect_scene(
    scene_file: &std::path::Path,
    scene: &grin_scene::Scene,
) -> grin_output::Protected {
    let dir = scene_file.parent().unwrap_or(std::path::Path::new("."));
    grin_output::protect_inputs(std::iter::once(scene_file.to_owned()).chain(scene.files(dir)))
}

/// `template` (indicatif's) with `=> ` filling the bar; the default bar where it does not
/// parse. Every subcommand's progress is drawn through it.
pub fn bar_style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).map_or_else(
        |_| ProgressStyle::default_bar(),
        |s| s.progress_chars("=> "),
    )
}

/// A progress bar of `len` steps drawn as `template` ([`bar_style`]).
pub fn styled_bar(len: u64, template: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(bar_style(template));
    bar
}
