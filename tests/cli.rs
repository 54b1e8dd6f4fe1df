//! End-to-end tests of the `grin` binary.

mod common;
use common::{data, grin, json, run_err, run_ok, scenes, stderr, stdout};

#[test]
fn help_lists_subcommands() {
    let text = stdout(&run_ok(grin().arg("--help")));
    for sub in ["trace", "bake", "render", "view", "info", "export", "bench"] {
        assert!(text.contains(sub), "help lacks `{sub}`: {text}");
    }
}

/// `grin info file | head`: a reader that closes the pipe early must not make grin panic.
#[test]
fn closed_stdout_is_not_a_crash() {
    let vdb = data("vdb/blender_fire.vdb");
    let mut child = grin()
        .arg("info")
        .arg(vdb)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run grin");
    // Close the read end before grin (which first opens the VDB file) writes anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait for grin");
    let stderr = stderr(&out);
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
    let scene = scenes().join("paper-c.toml");
    let out = grin()
        .args(["bench", "bake", "--scene"])
        .arg(scene)
        .args(["--rays", "0"])
        .output()
        .expect("run grin");
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("invalid value '0' for '--rays <RAYS>'"),
        "{err}"
    );
    assert!(err.contains("1..=16777216"), "{err}");
    assert!(out.stdout.is_empty());
}

/// CI's smoke test of `grin bench accuracy --quick` and `grin bench stability --quick`:
/// both finish, write their files and report JSON a script can read.
#[test]
fn bench_accuracy_and_stability_quick_smoke() {
    let dir = tempfile::tempdir().expect("temp dir");
    let acc = dir.path().join("acc");
    let v = json(&run_ok(
        grin()
            .args(["bench", "accuracy", "--quick", "--json", "-o"])
            .arg(&acc),
    ));
    assert_eq!(v["failed_runs"], 0, "{v}");
    let orders = v["orders"].as_array().expect("orders");
    let verlet = orders
        .iter()
        .find(|o| o["case"] == "luneburg" && o["integrator"] == "verlet" && o["precision"] == "f64")
        .expect("verlet order on the Luneburg lens");
    let slope = verlet["measured"].as_f64().expect("measured order");
    assert!((slope - 2.0).abs() < 0.3, "verlet order {slope}");
    for f in [
        "accuracy.csv",
        "orders.csv",
        "summary.md",
        "chart-luneburg-f64.svg",
        "chart-luneburg-f64.png",
    ] {
        assert!(acc.join(f).is_file(), "missing {f}");
    }

    run_err(
        grin()
            .args(["bench", "accuracy", "--quick", "--case", "nope", "-o"])
            .arg(dir.path().join("none")),
        "--case nope: no case of this suite matches (cases: luneburg, plume,",
    );

    let stab = dir.path().join("stab");
    let v = json(&run_ok(
        grin()
            .args(["bench", "stability", "--quick", "--json", "-o"])
            .arg(&stab),
    ));
    let cells = v["cells"].as_array().expect("cells");
    assert!(cells.len() >= 8 * 18, "{} cells", cells.len());
    assert!(cells.iter().all(|c| c["nan"] == false), "a cell wrote NaN");
    let md = std::fs::read_to_string(stab.join("stability.md")).expect("stability.md");
    assert!(md.contains("turning point below a face"));
}
