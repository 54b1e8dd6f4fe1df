//! End-to-end tests of where grin's outputs go: `-` and streams, symbolic links, missing
//! directories, a full disk (a tmpfs of our own inside `unshare -m`), and a signal in the
//! write phase. No test writes to the real /dev: streams are links we make to our own
//! stdout (/proc/self/fd/1) or /dev/null, written through.

use common::{assert_failed, assert_ok, data, run_ok, stderr, stdout};
use grin_testkit as common;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn grin() -> Command {
    let mut c = common::grin();
    c.env("NODEVICE_SELECT", "1");
    c
}

const RAYS: &str = "ox,oy,oz,dx,dy,dz\n0,0.5,-3,0,0,1\n0.2,0.5,-3,0,0,1\n";

fn rays(dir: &Path) -> PathBuf {
    let p = dir.join("rays.csv");
    std::fs::write(&p, RAYS).expect("rays");
    p
}

fn trace_to(dir: &Path, out: &Path) -> std::process::Output {
    common::trace_cmd(&data("scenes/luneburg.toml"), &rays(dir), out)
        .output()
        .expect("run grin")
}

fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("ls")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".grin-"))
        .collect()
}

#[test]
fn dash_and_stdout_links_write_the_table_to_stdout() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = trace_to(dir.path(), Path::new("-"));
    assert_ok(&out);
    let table = stdout(&out);
    assert!(table.starts_with("ox,oy,oz,dx,dy,dz,status,"), "{table}");
    assert_eq!(table.lines().count(), 3, "{table}");
    assert!(!dir.path().join("-").exists() && !Path::new("-").exists());
    // Our own link to our own stdout, like /dev/stdout: written through, kept a link.
    let link = dir.path().join("stdout");
    std::os::unix::fs::symlink("/proc/self/fd/1", &link).expect("link");
    let out = trace_to(dir.path(), &link);
    assert_ok(&out);
    assert!(stdout(&out).starts_with("ox,oy,oz"));
    let meta = std::fs::symlink_metadata(&link).expect("meta");
    assert!(meta.file_type().is_symlink(), "the link was replaced");
    // A link to a device: written into, the device untouched.
    let null = dir.path().join("null");
    std::os::unix::fs::symlink("/dev/null", &null).expect("link");
    let out = trace_to(dir.path(), &null);
    assert_ok(&out);
    assert!(
        std::fs::symlink_metadata(&null)
            .expect("meta")
            .file_type()
            .is_symlink()
    );
    assert!(!std::fs::metadata("/dev/null").expect("meta").is_file());
}

#[test]
fn a_link_to_a_file_keeps_the_link_and_replaces_the_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let real = dir.path().join("real.csv");
    std::fs::write(&real, "old").expect("seed");
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink(&real, &link).expect("link");
    let out = trace_to(dir.path(), &link);
    assert_ok(&out);
    assert!(
        std::fs::symlink_metadata(&link)
            .expect("meta")
            .file_type()
            .is_symlink()
    );
    assert!(
        std::fs::read_to_string(&real)
            .expect("read")
            .starts_with("ox,oy,oz")
    );
    assert!(temp_files(dir.path()).is_empty());
}

#[test]
fn missing_and_unwritable_targets_are_clear_errors() {
    let dir = tempfile::tempdir().expect("tmp");
    let missing = dir.path().join("nope/out.csv");
    let out = trace_to(dir.path(), &missing);
    let err = assert_failed(&out);
    assert!(
        err.contains(&format!(
            "{}: cannot write: directory {} does not exist",
            missing.display(),
            dir.path().join("nope").display()
        )),
        "{err}"
    );
    assert!(!err.contains("os error"), "{err}");
    // A read-only filesystem (a bind mount of our own; root ignores file modes).
    let ro = dir.path().join("ro");
    std::fs::create_dir(&ro).expect("mkdir");
    std::fs::write(ro.join("out.csv"), "keep").expect("seed");
    let script = format!(
        "mount --bind {ro} {ro} && mount -o remount,bind,ro {ro} && exec {grin} trace {scene} --rays {rays} -o {ro}/out.csv",
        ro = ro.display(),
        grin = env!("CARGO_BIN_EXE_grin"),
        scene = data("scenes/luneburg.toml").display(),
        rays = rays(dir.path()).display(),
    );
    let out = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output()
        .expect("unshare");
    let err = assert_failed(&out);
    assert!(
        err.contains("out.csv: cannot write: cannot create a file in"),
        "{err}"
    );
    assert!(err.contains("Read-only file system"), "{err}");
    assert_eq!(
        std::fs::read_to_string(ro.join("out.csv")).expect("read"),
        "keep"
    );
}

#[test]
fn export_onto_a_full_disk_fails_and_keeps_the_old_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let grinf = dir.path().join("f.grinf");
    run_ok(
        grin()
            .arg("bake")
            .arg(data("scenes/luneburg.toml"))
            .args(["--resolution", "48", "-o"])
            .arg(&grinf),
    );
    let mnt = dir.path().join("small");
    std::fs::create_dir(&mnt).expect("mkdir");
    // 64 KiB of tmpfs holds the old file but not a 48^3 export.
    let script = format!(
        "mount -t tmpfs -o size=64k tmpfs {mnt} && printf old > {mnt}/out.vdb && \
         {grin} export {grinf} -o {mnt}/out.vdb; echo \"rc=$?\"; cat {mnt}/out.vdb; echo; ls -a {mnt}",
        mnt = mnt.display(),
        grin = env!("CARGO_BIN_EXE_grin"),
        grinf = grinf.display(),
    );
    let out = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output()
        .expect("unshare");
    let stdout = stdout(&out);
    let stderr = stderr(&out);
    let mut lines = stdout.lines();
    assert_eq!(lines.next(), Some("rc=1"), "{stdout}\n{stderr}");
    assert_eq!(
        lines.next(),
        Some("old"),
        "the old file was replaced: {stdout}"
    );
    assert!(!stdout.contains(".grin-"), "temporary file left: {stdout}");
    assert!(stderr.contains("out.vdb: "), "{stderr}");
    assert!(
        !stderr.contains(".grin-"),
        "the error names the temporary file: {stderr}"
    );
}

#[test]
fn sigterm_in_the_write_phase_leaves_the_old_pair_and_no_temp_files() {
    let dir = tempfile::tempdir().expect("tmp");
    let (exr, png) = (dir.path().join("x.exr"), dir.path().join("x.png"));
    std::fs::write(&exr, "old exr").expect("seed");
    std::fs::write(&png, "old png").expect("seed");
    let mut child = grin()
        .arg("render")
        .arg(data("scenes/luneburg.toml"))
        .arg("-o")
        .arg(&exr)
        .args(["--backend", "cpu", "--size", "32x18", "--spp", "1"])
        .env("GRIN_TEST_PAUSE_BEFORE_COMMIT_MS", "20000")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // Wait until both outputs are staged (two temporary files), then interrupt.
    let start = Instant::now();
    while temp_files(dir.path()).len() < 2 {
        assert!(start.elapsed() < Duration::from_secs(60), "never staged");
        assert!(child.try_wait().expect("status").is_none(), "exited early");
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    let killed = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill");
    assert!(killed.success());
    let out = child.wait_with_output().expect("wait");
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(
        temp_files(dir.path()).is_empty(),
        "{:?}",
        temp_files(dir.path())
    );
    assert_eq!(std::fs::read_to_string(&exr).expect("exr"), "old exr");
    assert_eq!(std::fs::read_to_string(&png).expect("png"), "old png");
    // Without the signal the pair is replaced together.
    run_ok(
        grin()
            .arg("render")
            .arg(data("scenes/luneburg.toml"))
            .arg("-o")
            .arg(&exr)
            .args(["--backend", "cpu", "--size", "32x18", "--spp", "1"]),
    );
    assert!(
        std::fs::read(&exr)
            .expect("exr")
            .starts_with(&[0x76, 0x2f, 0x31, 0x01])
    );
    assert!(std::fs::read(&png).expect("png").starts_with(b"\x89PNG"));
}

#[test]
fn render_to_dash_streams_the_exr_and_reports_on_stderr() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = grin()
        .current_dir(dir.path())
        .arg("render")
        .arg(data("scenes/luneburg.toml"))
        .args([
            "-o",
            "-",
            "--backend",
            "cpu",
            "--size",
            "16x9",
            "--spp",
            "1",
        ])
        .output()
        .expect("render");
    assert_ok(&out);
    let err = stderr(&out);
    assert!(
        out.stdout.starts_with(&[0x76, 0x2f, 0x31, 0x01]),
        "stdout is not an EXR"
    );
    assert!(
        err.contains("no PNG preview is written") && err.contains("rendered 16x9"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(dir.path()).expect("ls").count(), 0);
}

/// Under an address-space limit, a frame or a bake grid that does not fit is a one-line
/// error naming what it was for (it used to abort: "memory allocation of ... failed").
#[test]
fn buffers_that_do_not_fit_are_errors_not_aborts() {
    let dir = tempfile::tempdir().expect("tmp");
    let run = |args: &str| {
        let script = format!(
            "ulimit -v 3000000; exec {} {args}",
            env!("CARGO_BIN_EXE_grin")
        );
        let out = Command::new("sh")
            .args(["-c", &script])
            .current_dir(dir.path())
            .output()
            .expect("sh");
        (out.status.code(), stderr(&out))
    };
    let scene = data("scenes/paper-a.toml");
    let (code, err) = run(&format!(
        "render {} -o big.exr --backend cpu --size 8192x8192 --spp 1",
        scene.display()
    ));
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("grin: error: not enough memory for a 8192x8192 frame: 4026531840 bytes"),
        "{err}"
    );
    let (code, err) = run(&format!(
        "bake {} --resolution 1500 --max-memory 100G -o b.grinf",
        data("scenes/luneburg.toml").display()
    ));
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("not enough memory for a 1504x1504x1504 baked grid"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(dir.path()).expect("ls").count(), 0);
}

/// A ray table from stdin (`--rays -`) with an `id` column, traced to stdout as JSON: the
/// id comes through, the JSON is valid and the summary (`--json`) goes to stderr.
#[test]
fn ray_tables_stream_through_with_extra_columns() {
    use std::io::Write;
    let mut child = grin()
        .arg("trace")
        .arg(data("scenes/luneburg.toml"))
        .args(["--rays", "-", "-o", "-", "--format", "json", "--json"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(b"id,ox,oy,oz,dx,dy,dz\nray-a,0,0.2,-3,0,0,1\nray-b,0,5,-3,0,0,1\n")
        .expect("write rays");
    let out = child.wait_with_output().expect("wait");
    assert_ok(&out);
    let err = stderr(&out);
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    assert_eq!(rows[0]["id"], "ray-a");
    assert_eq!(rows[0]["status"], "exited");
    assert_eq!(rows[1]["id"], "ray-b");
    assert_eq!(rows[1]["status"], "missed");
    let summary = err
        .lines()
        .find(|l| l.starts_with('{'))
        .expect("summary on stderr");
    let summary: serde_json::Value = serde_json::from_str(summary).expect("summary JSON");
    assert_eq!(summary["rays"], 2);
    assert!(
        summary["step"].is_object(),
        "step as the scene writes it: {summary}"
    );
}
