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

/// `grin info file | head`: a reader that closes the pipe early must not make grin panic.
#[test]
fn closed_stdout_is_not_a_crash() {
    let vdb = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/vdb/blender_fire.vdb"
    );
    let mut child = grin()
        .args(["info", vdb])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run grin");
    // Close the read end before grin (which first opens the VDB file) writes anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait for grin");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "grin panicked: {stderr}");
    assert!(
        out.status.success() || out.status.code() == Some(141),
        "unexpected exit {:?}: {stderr}",
        out.status
    );
}

/// `bench bake --rays 0` used to print speedups computed from zero evaluations.
#[test]
fn bench_bake_refuses_zero_rays() {
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/scenes/paper-c.toml"
    );
    let out = grin()
        .args(["bench", "bake", "--scene", scene, "--rays", "0"])
        .output()
        .expect("run grin");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("invalid value '0' for '--rays <RAYS>'"),
        "{err}"
    );
    assert!(err.contains("1..=16777216"), "{err}");
    assert!(out.stdout.is_empty());
}
