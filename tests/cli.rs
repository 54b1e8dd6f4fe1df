//! End-to-end tests of the `grin` binary.

use std::process::Command;

fn grin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_grin"))
}

#[test]
fn help_lists_subcommands() {
    let out = grin().arg("--help").output().expect("run grin");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["trace", "bake", "render", "view", "info", "export", "bench"] {
        assert!(text.contains(sub), "help lacks `{sub}`: {text}");
    }
}
