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
