//! End-to-end tests of the `grin` binary.

use common::{data, grin, json, run_err, run_ok, scenes, stderr, stdout};
use grin_testkit as common;

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

/// An output named like one of the run's inputs (the scene, the baked file exported, the
/// ray table, a plate the scene shows, under its own name or through a link) is refused
/// before anything is written, naming the input, and the input is left as it was.
#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = common::TestDir::new();
    let scene_text = std::fs::read_to_string(scenes().join("plume.toml")).expect("scene");
    let scene = dir.write("plume.toml", &scene_text);
    let kept = |path: &std::path::Path, before: &[u8]| {
        assert_eq!(
            std::fs::read(path).expect("input"),
            before,
            "{}",
            path.display()
        );
    };
    let needle = "an input of this run: the output would replace it";

    // `grin bake` onto its scene, directly and through a link to it.
    run_err(grin().arg("bake").arg(&scene).arg("-o").arg(&scene), needle);
    let link = dir.path("link.grinf");
    std::os::unix::fs::symlink(&scene, &link).expect("link");
    let out = run_err(grin().arg("bake").arg(&scene).arg("-o").arg(&link), needle);
    assert!(stderr(&out).contains("plume.toml"), "{}", stderr(&out));
    kept(&scene, scene_text.as_bytes());

    // `grin export` onto the file it exports.
    let baked = dir.path("plume.grinf");
    let opts = ["--resolution", "12"];
    run_ok(
        grin()
            .arg("bake")
            .arg(&scene)
            .args(opts)
            .arg("-o")
            .arg(&baked),
    );
    let bytes = std::fs::read(&baked).expect("bake");
    run_err(
        grin().arg("export").arg(&baked).arg("-o").arg(&baked),
        needle,
    );
    kept(&baked, &bytes);

    // `grin trace` onto its ray table.
    let rays = dir.write("rays.csv", "ox,oy,oz,dx,dy,dz\n0,0,-5,0,0,1\n");
    let table = std::fs::read(&rays).expect("rays");
    run_err(&mut common::trace_cmd(&scene, &rays, &rays), needle);
    kept(&rays, &table);

    // `grin render -o street.exr` whose PNG preview would replace the scene's plate.
    let plate = dir.path("street.png");
    std::fs::copy(data("images/street.png"), &plate).expect("plate");
    let image = std::fs::read(&plate).expect("plate");
    let plated = dir.write(
        "plated.toml",
        &scene_text.replace(
            "gradient = { horizon = [0.95, 0.92, 0.85], zenith = [0.3, 0.5, 0.9], ground = [0.3, 0.28, 0.25] }",
            "plate = { path = \"street.png\" }",
        ),
    );
    let out = run_err(
        grin()
            .args(["render", "--backend", "cpu", "--size", "8x6", "-o"])
            .arg(dir.path("street.exr"))
            .arg(&plated),
        needle,
    );
    assert!(stderr(&out).contains("street.png"), "{}", stderr(&out));
    kept(&plate, &image);
    assert!(!dir.path("street.exr").exists(), "no EXR is written");
}
