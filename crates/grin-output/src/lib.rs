//! Files grin writes. Every output is first written in full to a temporary file (in a
//! private `.grin-*` directory beside its target, so the final rename stays on one
//! filesystem and a signal can remove it for good), synced, and only then put in place;
//! several outputs of one run (an EXR and its PNG preview) are put in place together
//! ([`commit`]), so a failed or interrupted run leaves the previous files as
//! they were and no temporary file behind.
//!
//! What a target path means ([`Destination::resolve`]):
//! - a regular file, or a path that does not exist yet in an existing directory: replaced
//!   atomically by a rename;
//! - a symbolic link to a regular file: the file it points to is replaced, the link kept
//!   (a rename over the link would turn `/dev/stdout` into a plain file);
//! - `-`: standard output, where the caller allows a stream;
//! - a character device, FIFO or socket (`/dev/stdout`, `/dev/null`, a named pipe): the
//!   finished bytes are copied into it, nothing is created or replaced;
//! - a directory, a dangling link, or a path in a missing directory: an error naming it.
//! - a file the run reads ([`protect_inputs`]: its scene, VDB, plate, ray table), under
//!   any name: an error naming it, so a mistyped `-o` cannot replace an input.
//!
//! [`install_signal_cleanup`] makes SIGINT and SIGTERM remove the staged temporary files
//! before the process exits; a commit in progress finishes first.

use std::collections::BTreeSet;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// Mode of a newly created output file (rw-r--r--).
const NEW_FILE_MODE: u32 = 0o644;

/// Exit status after SIGINT or SIGTERM cleaned up (128 + SIGINT, what a shell reports).
pub const INTERRUPTED_EXIT_CODE: i32 = 130;

/// Test hook: milliseconds to sleep after every output is staged and before any is put in
/// place, so a test can interrupt a run exactly in its write phase.
pub const PAUSE_BEFORE_COMMIT_ENV: &str = "GRIN_TEST_PAUSE_BEFORE_COMMIT_MS";

/// Why an output could not be written; each names the target the user gave.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{}: cannot write: {reason}", path.display())]
    Target { path: PathBuf, reason: String },
    /// The io::Error is in the message, not a `source()`: `{:#}` would print it twice.
    #[error("{}: cannot write: {}", path.display(), plain(err))]
    Io { path: PathBuf, err: io::Error },
    #[error("{}: {message}", path.display())]
    Writer { path: PathBuf, message: String },
}

impl OutputError {
    fn target(path: &Path, reason: impl Into<String>) -> Self {
        OutputError::Target {
            path: path.to_owned(),
            reason: reason.into(),
        }
    }
    fn io(path: &Path, source: io::Error) -> Self {
        OutputError::Io {
            path: path.to_owned(),
            err: source,
        }
    }
}

/// Where the bytes of one output end up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Destination {
    /// A regular file, replaced by a rename of a temporary file in `dir`.
    Replace { file: PathBuf },
    /// A device, FIFO or socket, written into as it is.
    Stream { file: PathBuf },
    /// Standard output (`-`).
    Stdout,
}

impl Destination {
    /// What writing to `path` means (see the module documentation).
    pub fn resolve(path: &Path) -> Result<Self, OutputError> {
        if path.as_os_str() == "-" {
            return Ok(Destination::Stdout);
        }
        match fs::metadata(path) {
            Ok(meta) if meta.is_file() => {
                if let Some(input) = input_at(&meta) {
                    return Err(OutputError::target(
                        path,
                        format!(
                            "it is {}, an input of this run: the output would replace it \
                             (name another output)",
                            input.display()
                        ),
                    ));
                }
                let file = fs::canonicalize(path).map_err(|e| OutputError::io(path, e))?;
                Ok(Destination::Replace { file })
            }
            Ok(meta) if meta.is_dir() => Err(OutputError::target(path, "it is a directory")),
            Ok(_) => Ok(Destination::Stream {
                file: path.to_owned(),
            }),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::NotFound | io::ErrorKind::NotADirectory
                ) =>
            {
                if let Ok(link) = fs::read_link(path) {
                    return Err(OutputError::target(
                        path,
                        format!(
                            "it is a symbolic link to {}, which does not exist; the link is \
                             not replaced",
                            link.display()
                        ),
                    ));
                }
                let name = path
                    .file_name()
                    .ok_or_else(|| OutputError::target(path, "it does not name a file"))?;
                let parent = match path.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p,
                    _ => Path::new("."),
                };
                match fs::metadata(parent) {
                    Ok(m) if m.is_dir() => {}
                    Ok(_) => {
                        return Err(OutputError::target(
                            path,
                            format!("{} is not a directory", parent.display()),
                        ));
                    }
                    Err(_) => {
                        return Err(OutputError::target(
                            path,
                            format!("directory {} does not exist", parent.display()),
                        ));
                    }
                }
                let dir = fs::canonicalize(parent).map_err(|e| OutputError::io(path, e))?;
                Ok(Destination::Replace {
                    file: dir.join(name),
                })
            }
            Err(e) => Err(OutputError::io(path, e)),
        }
    }

    /// True where the output is written into an existing stream rather than a file.
    pub fn is_stream(&self) -> bool {
        !matches!(self, Destination::Replace { .. })
    }
}

/// A file being read: its device and inode (a link or another name for it is the same
/// file), the name it was given, and how many [`Protected`] guards hold it.
struct Input {
    id: (u64, u64),
    path: PathBuf,
    guards: usize,
}

/// The files being read: no output may replace one.
static INPUTS: Mutex<Vec<Input>> = Mutex::new(Vec::new());

fn inputs() -> MutexGuard<'static, Vec<Input>> {
    INPUTS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Files declared inputs by [`protect_inputs`], until this is dropped.
#[derive(Debug)]
#[must_use = "the inputs are protected only while the guard lives"]
pub struct Protected {
    ids: Vec<(u64, u64)>,
}

impl Drop for Protected {
    fn drop(&mut self) {
        let mut inputs = inputs();
        for id in &self.ids {
            if let Some(i) = inputs.iter().position(|x| x.id == *id) {
                inputs[i].guards -= 1;
                if inputs[i].guards == 0 {
                    inputs.swap_remove(i);
                }
            }
        }
    }
}

/// Declare files a run reads (a scene, its VDB, a plate, a ray table) while the guard
/// lives: an output that is one of them, under any name, is refused
/// ([`Destination::resolve`] says which), so `-o` given an input's name cannot destroy
/// it. Paths that are not files are passed over.
pub fn protect_inputs<P: AsRef<Path>>(paths: impl IntoIterator<Item = P>) -> Protected {
    use std::os::unix::fs::MetadataExt;
    let mut inputs = inputs();
    let mut ids = Vec::new();
    for p in paths {
        let p = p.as_ref();
        let Ok(meta) = fs::metadata(p) else { continue };
        let id = (meta.dev(), meta.ino());
        if !meta.is_file() || ids.contains(&id) {
            continue;
        }
        match inputs.iter_mut().find(|x| x.id == id) {
            Some(entry) => entry.guards += 1,
            None => inputs.push(Input {
                id,
                path: p.to_owned(),
                guards: 1,
            }),
        }
        ids.push(id);
    }
    Protected { ids }
}

/// The protected input that `meta` is, if any.
fn input_at(meta: &fs::Metadata) -> Option<PathBuf> {
    use std::os::unix::fs::MetadataExt;
    let id = (meta.dev(), meta.ino());
    inputs().iter().find(|x| x.id == id).map(|x| x.path.clone())
}

/// Staging directories not yet put in place or removed, for the signal handler.
static LIVE: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());

fn live() -> MutexGuard<'static, BTreeSet<PathBuf>> {
    LIVE.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Name of the staged file inside its private staging directory.
const STAGED_NAME: &str = "staged";

/// Remove a staging directory and what is in it. A writer that opens its file by path
/// may create it again while the directory is being emptied; once the directory itself
/// is gone, nothing can be created in it, so this tries until it is.
fn remove_staging(dir: &Path) {
    for _ in 0..100 {
        match fs::remove_dir_all(dir) {
            Err(e) if e.kind() != io::ErrorKind::NotFound && dir.exists() => continue,
            _ => return,
        }
    }
}

/// A private directory holding one staged output. Writers that only take a path (EXR,
/// OpenVDB) open the staged file by name, so removing the file alone could race with
/// them creating it again; removing its directory cannot.
#[derive(Debug)]
struct Staging {
    dir: PathBuf,
}

impl Staging {
    fn file(&self) -> PathBuf {
        self.dir.join(STAGED_NAME)
    }

    /// Remove the directory and take it out of `live` (the set whose lock the caller
    /// holds: `commit`'s).
    fn remove(mut self, live: &mut BTreeSet<PathBuf>) {
        let dir = std::mem::take(&mut self.dir);
        remove_staging(&dir);
        live.remove(&dir);
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        // An empty path: already removed by `Staging::remove`.
        if !self.dir.as_os_str().is_empty() {
            remove_staging(&self.dir);
            live().remove(&self.dir);
        }
    }
}

/// One output written in full to a temporary file, waiting for [`commit`]. Dropped
/// without a commit, its temporary file is removed.
#[derive(Debug)]
pub struct Staged {
    /// The path as the user gave it (for messages).
    target: PathBuf,
    destination: Destination,
    staging: Option<Staging>,
}

/// Why [`stage_with`] failed: the target could not be staged, or the caller's writer
/// failed with its own error.
#[derive(Debug)]
pub enum StageError<E> {
    Output(OutputError),
    Writer(E),
}

impl<E> From<OutputError> for StageError<E> {
    fn from(e: OutputError) -> Self {
        StageError::Output(e)
    }
}

/// Stage `target` by letting `write` write the whole output to the temporary file whose
/// path it is given (for writers that only take a path: EXR, OpenVDB), keeping the
/// writer's own error type. The file is synced before this returns, so a full disk fails
/// here and not after a rename.
pub fn stage_with<E>(
    target: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<Staged, StageError<E>> {
    let destination = Destination::resolve(target)?;
    let dir = match &destination {
        Destination::Replace { file } => file
            .parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
        _ => std::env::temp_dir(),
    };
    let staging = {
        // Registered before the directory exists, so a signal in between removes it too.
        let mut guard = live();
        let cannot = |e: io::Error| {
            OutputError::target(
                target,
                format!("cannot create a file in {}: {}", dir.display(), plain(&e)),
            )
        };
        let made = tempfile::Builder::new()
            .prefix(".grin-")
            .tempdir_in(&dir)
            .map_err(cannot)?
            .keep();
        guard.insert(made.clone());
        let staging = Staging { dir: made };
        OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(staging.file())
            .map_err(cannot)?;
        staging
    };
    let tmp_path = staging.file();
    let staged = Staged {
        target: target.to_owned(),
        destination,
        staging: Some(staging),
    };
    write(&tmp_path).map_err(StageError::Writer)?;
    // tempfile creates its files 0600; an output gets the mode of the file it replaces,
    // or the usual 0644.
    let mode = match &staged.destination {
        Destination::Replace { file } => fs::metadata(file)
            .map(|m| m.permissions().mode() & 0o7777)
            .unwrap_or(NEW_FILE_MODE),
        _ => NEW_FILE_MODE,
    };
    fs::set_permissions(&tmp_path, fs::Permissions::from_mode(mode))
        .and_then(|()| File::open(&tmp_path))
        .and_then(|f| f.sync_all())
        .map_err(|e| OutputError::io(target, e))?;
    Ok(staged)
}

/// [`stage_with`] for writers whose errors are text; a message naming the temporary file
/// names the target instead.
pub fn stage_path(
    target: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<Staged, OutputError> {
    let mut tmp_shown = String::new();
    stage_with(target, |tmp| {
        tmp_shown = tmp.display().to_string();
        write(tmp)
    })
    .map_err(|e| match e {
        StageError::Output(e) => e,
        StageError::Writer(message) => OutputError::Writer {
            path: target.to_owned(),
            message: message.replace(&tmp_shown, &target.display().to_string()),
        },
    })
}

/// Stage `target` by letting `write` write into a buffered writer (flushed here; synced
/// by [`stage_with`], so every write error surfaces).
pub fn stage_writer(
    target: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<Staged, OutputError> {
    stage_with(target, |tmp| {
        let mut w = io::BufWriter::new(File::create(tmp)?);
        write(&mut w)?;
        w.flush()
    })
    .map_err(|e| match e {
        StageError::Output(e) => e,
        StageError::Writer(err) => OutputError::io(target, err),
    })
}

/// Put every staged output in place, in order. The signal handler waits while this runs.
/// Where one fails, those not yet placed are removed and the error names it.
pub fn commit(staged: Vec<Staged>) -> Result<(), OutputError> {
    if let Some(ms) = std::env::var(PAUSE_BEFORE_COMMIT_ENV)
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
    let mut guard = live();
    for mut s in staged {
        let Some(staging) = s.staging.take() else {
            continue;
        };
        let tmp_path = staging.file();
        let result = match &s.destination {
            Destination::Replace { file } => {
                fs::rename(&tmp_path, file).map_err(|e| OutputError::io(&s.target, e))
            }
            Destination::Stream { file } => OpenOptions::new()
                .write(true)
                .open(file)
                .and_then(|mut out| copy_into(&tmp_path, &mut out))
                .map_err(|e| OutputError::io(&s.target, e)),
            Destination::Stdout => copy_into(&tmp_path, &mut io::stdout().lock())
                .map_err(|e| OutputError::io(&s.target, e)),
        };
        staging.remove(&mut guard);
        result?;
    }
    Ok(())
}

fn copy_into(tmp: &Path, out: &mut dyn Write) -> io::Result<()> {
    let mut file = File::open(tmp)?;
    io::copy(&mut file, out)?;
    out.flush()
}

/// Stage and commit one output written through a buffered writer.
pub fn write_file(
    target: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), OutputError> {
    commit(vec![stage_writer(target, write)?])
}

/// An io::Error's text without Rust's " (os error N)" suffix, for one-line messages.
pub fn plain(e: &io::Error) -> String {
    let text = e.to_string();
    match text.find(" (os error ") {
        Some(i) => text[..i].to_owned(),
        None => text,
    }
}

/// On SIGINT or SIGTERM: wait for a commit in progress, remove every staged temporary
/// file, and exit with [`INTERRUPTED_EXIT_CODE`]. Call once, early in `main`.
pub fn install_signal_cleanup() -> Result<(), String> {
    ctrlc::set_handler(|| {
        // Held until the process is gone: nothing is staged or committed after this.
        let mut guard = live();
        for dir in guard.iter() {
            remove_staging(dir);
        }
        guard.clear();
        eprintln!("grin: interrupted; no output was left half-written");
        std::process::exit(INTERRUPTED_EXIT_CODE);
    })
    .map_err(|e| format!("cannot install the signal handler: {e}"))
}

#[cfg(test)]
mod tests;
