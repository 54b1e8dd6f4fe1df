use std::os::unix::fs::PermissionsExt;

use super::*;

fn no_temp_files(dir: &Path) -> bool {
    fs::read_dir(dir).expect("dir").all(|e| {
        !e.expect("entry")
            .file_name()
            .to_string_lossy()
            .starts_with(".grin-")
    })
}

#[test]
fn new_and_replaced_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("a.txt");
    write_file(&out, |w| w.write_all(b"first")).expect("new");
    assert_eq!(fs::read(&out).expect("read"), b"first");
    assert_eq!(
        fs::metadata(&out).expect("meta").permissions().mode() & 0o777,
        0o644
    );
    fs::set_permissions(&out, fs::Permissions::from_mode(0o640)).expect("chmod");
    write_file(&out, |w| w.write_all(b"second")).expect("replace");
    assert_eq!(fs::read(&out).expect("read"), b"second");
    assert_eq!(
        fs::metadata(&out).expect("meta").permissions().mode() & 0o777,
        0o640
    );
    assert!(no_temp_files(dir.path()));
}

#[test]
fn long_file_names_fit() {
    // The temporary name is short and fixed: a 250-byte target name still works.
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join(format!("{}.csv", "n".repeat(246)));
    write_file(&out, |w| w.write_all(b"x")).expect("250-byte name");
    assert_eq!(fs::read(&out).expect("read"), b"x");
}

#[test]
fn a_failed_writer_leaves_the_old_file_and_no_temp() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("keep.txt");
    fs::write(&out, b"good").expect("seed");
    let e = write_file(&out, |w| {
        w.write_all(b"half")?;
        Err(io::Error::other("disk on fire"))
    })
    .expect_err("writer fails");
    assert_eq!(
        e.to_string(),
        format!("{}: cannot write: disk on fire", out.display())
    );
    assert_eq!(fs::read(&out).expect("read"), b"good");
    assert!(no_temp_files(dir.path()));
}

#[test]
fn outputs_of_one_commit_land_together_or_not_at_all() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (a, b) = (dir.path().join("x.exr"), dir.path().join("x.png"));
    fs::write(&a, b"old a").expect("seed");
    fs::write(&b, b"old b").expect("seed");
    let first = stage_writer(&a, |w| w.write_all(b"new a")).expect("stage a");
    let second = stage_writer(&b, |_| Err(io::Error::other("png encoder failed")));
    assert!(second.is_err());
    drop(first); // the caller gives up: nothing was put in place
    assert_eq!(fs::read(&a).expect("read"), b"old a");
    assert_eq!(fs::read(&b).expect("read"), b"old b");
    assert!(no_temp_files(dir.path()));
    let first = stage_writer(&a, |w| w.write_all(b"new a")).expect("stage a");
    let second = stage_writer(&b, |w| w.write_all(b"new b")).expect("stage b");
    commit(vec![first, second]).expect("commit");
    assert_eq!(fs::read(&a).expect("read"), b"new a");
    assert_eq!(fs::read(&b).expect("read"), b"new b");
    // None of this test's temporary files is left to clean up (other tests stage theirs
    // in other directories at the same time).
    let here = fs::canonicalize(dir.path()).expect("dir");
    assert!(live().iter().all(|p| !p.starts_with(&here)), "{:?}", live());
}

#[test]
fn a_symlink_target_keeps_the_link() {
    let dir = tempfile::tempdir().expect("tempdir");
    let real = dir.path().join("real.txt");
    let link = dir.path().join("link.txt");
    fs::write(&real, b"old").expect("seed");
    std::os::unix::fs::symlink(&real, &link).expect("symlink");
    write_file(&link, |w| w.write_all(b"through the link")).expect("write");
    assert!(
        fs::symlink_metadata(&link)
            .expect("meta")
            .file_type()
            .is_symlink()
    );
    assert_eq!(fs::read(&real).expect("read"), b"through the link");
    let dangling = dir.path().join("dangling.txt");
    std::os::unix::fs::symlink(dir.path().join("nowhere.txt"), &dangling).expect("symlink");
    let e = write_file(&dangling, |w| w.write_all(b"x")).expect_err("dangling");
    assert!(
        e.to_string()
            .contains("nowhere.txt, which does not exist; the link is not replaced"),
        "{e}"
    );
    assert!(
        fs::symlink_metadata(&dangling)
            .expect("meta")
            .file_type()
            .is_symlink()
    );
}

#[test]
fn devices_are_written_into_not_replaced() {
    let before = fs::symlink_metadata("/dev/null").expect("meta");
    write_file(Path::new("/dev/null"), |w| w.write_all(b"discarded")).expect("device");
    let after = fs::symlink_metadata("/dev/null").expect("meta");
    assert!(!after.file_type().is_file());
    assert_eq!(before.file_type(), after.file_type());
    assert_eq!(
        Destination::resolve(Path::new("-")).expect("-"),
        Destination::Stdout
    );
}

#[test]
fn missing_directories_and_directories_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("no/such/dir/out.csv");
    let e = write_file(&missing, |w| w.write_all(b"x")).expect_err("missing dir");
    assert_eq!(
        e.to_string(),
        format!(
            "{}: cannot write: directory {} does not exist",
            missing.display(),
            dir.path().join("no/such/dir").display()
        )
    );
    let e = write_file(dir.path(), |w| w.write_all(b"x")).expect_err("a directory");
    assert!(
        e.to_string().ends_with("cannot write: it is a directory"),
        "{e}"
    );
    let file = dir.path().join("plain");
    fs::write(&file, b"").expect("seed");
    let e = write_file(&file.join("out.csv"), |w| w.write_all(b"x")).expect_err("not a dir");
    assert!(e.to_string().ends_with("plain is not a directory"), "{e}");
}

#[test]
fn os_error_text_is_plain() {
    let e = io::Error::from_raw_os_error(2);
    assert_eq!(plain(&e), "No such file or directory");
}

/// A protected input refuses outputs under its name, a hard link's and a symbolic link's,
/// while any guard holding it lives; a second guard on the same file keeps it protected
/// after the first is dropped, and with both gone it is an ordinary output again.
#[test]
fn protected_inputs_refuse_outputs_while_a_guard_lives() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("scene.toml");
    fs::write(&input, b"scene").expect("input");
    let hard = dir.path().join("hard.toml");
    fs::hard_link(&input, &hard).expect("hard link");
    let soft = dir.path().join("soft.toml");
    std::os::unix::fs::symlink(&input, &soft).expect("symlink");
    let refused = |target: &Path| match write_file(target, |w| w.write_all(b"out")) {
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("an input of this run"), "{msg}");
            assert!(msg.contains("scene.toml"), "{msg}");
        }
        Ok(()) => panic!("{} was replaced", target.display()),
    };
    let first = protect_inputs([&input, &dir.path().join("missing.toml")]);
    let second = protect_inputs([&hard]);
    for target in [&input, &hard, &soft] {
        refused(target);
    }
    drop(first);
    refused(&soft);
    assert_eq!(fs::read(&input).expect("read"), b"scene");
    assert!(no_temp_files(dir.path()));
    drop(second);
    write_file(&soft, |w| w.write_all(b"out")).expect("free again");
    assert_eq!(fs::read(&input).expect("read"), b"out");
}

#[test]
fn a_writer_that_reopens_its_file_after_the_cleanup_leaves_nothing() {
    // The signal handler's cleanup may run between a file being staged and a path-only
    // writer (EXR, OpenVDB) opening it by name: the writer must not create it again.
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("late.exr");
    let result = stage_path(&out, |tmp| {
        // What the handler does to each directory (all of them there, which here would
        // reach the other tests' outputs too).
        remove_staging(tmp.parent().expect("staged in a directory"));
        fs::write(tmp, b"written after the cleanup").map_err(|e| plain(&e))
    });
    let e = result.expect_err("the staging directory is gone");
    assert!(
        e.to_string()
            .starts_with(&format!("{}: No such file or directory", out.display())),
        "{e}"
    );
    assert!(!out.exists());
    assert!(no_temp_files(dir.path()));
}
