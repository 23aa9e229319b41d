//! Safe outputs for every command that writes files.
//!
//! - Atomic files: [`write_atomic`] writes a temporary file in the target's directory, syncs it
//!   and renames it over the target, so a killed command leaves the old file or none, never
//!   half of one.
//! - Inputs are never outputs: a command registers its inputs with [`protect_inputs`]; from then
//!   on [`write_atomic`] refuses a path that is (canonically, or as the same file through a hard
//!   link) one of them. `diagnose in.csv --json in.csv` is refused instead of replacing the log.
//! - Output directories are claimed: [`OutputDir::open`] accepts a directory that is missing,
//!   empty, or holds the manifest ([`MANIFEST`]) of the same command with the same inputs (a
//!   re-run); a directory with other files, or the manifest of another run, needs `--force`.
//!   The manifest is written first as incomplete and completed last, after every file of the
//!   set, so a reader can tell a finished set from an interrupted one.

use std::fmt;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde_json::{json, Value};

/// The manifest a command writes into its output directory, naming itself and its files.
pub const MANIFEST: &str = "hil-host-manifest.json";
/// Temporary files in an output directory start with this (left-overs of a killed command are
/// ignored when a directory is judged empty).
pub const TMP_PREFIX: &str = ".hil-host-tmp-";

/// The canonical paths of the running command's inputs (see [`protect_inputs`]).
static PROTECTED: Mutex<Vec<Protected>> = Mutex::new(Vec::new());

#[derive(Clone, Debug)]
struct Protected {
    shown: PathBuf,
    canonical: PathBuf,
}

/// Registers the command's input files: [`write_atomic`] (and so every writer of this crate)
/// refuses to replace them for the rest of the process. Paths that do not exist are skipped
/// (reading them fails on its own).
pub fn protect_inputs<P: AsRef<Path>>(inputs: &[P]) {
    let mut list = PROTECTED.lock().unwrap_or_else(|p| p.into_inner());
    for p in inputs {
        let p = p.as_ref();
        if let Ok(canonical) = p.canonicalize() {
            list.push(Protected {
                shown: p.to_path_buf(),
                canonical,
            });
        }
    }
}

/// Where `path` resolves to, for paths that may not exist yet: its canonical directory joined
/// with its file name.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(c) = path.canonicalize() {
        return Some(c);
    }
    let name = path.file_name()?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    parent.canonicalize().ok().map(|d| d.join(name))
}

#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &Path, _: &Path) -> bool {
    false
}

/// The registered input that `path` would overwrite, if any.
pub fn input_at(path: &Path) -> Option<PathBuf> {
    let list = PROTECTED.lock().unwrap_or_else(|p| p.into_inner());
    let target = resolved(path)?;
    list.iter()
        .find(|p| p.canonical == target || same_file(&p.canonical, path))
        .map(|p| p.shown.clone())
}

/// Refuses `path` when it is one of the command's inputs.
pub fn check_not_input(path: &Path) -> io::Result<()> {
    match input_at(path) {
        Some(input) => Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "refusing to write {}: it is the input {} of this command",
                path.display(),
                input.display()
            ),
        )),
        None => Ok(()),
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, synced, then
/// renamed over `path`. Refuses the command's inputs ([`protect_inputs`]). The file gets the
/// old file's permissions, or the usual 0644 for a new one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    check_not_input(path)?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::Builder::new().prefix(TMP_PREFIX).tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    let permissions = match std::fs::metadata(path) {
        Ok(m) => Some(m.permissions()),
        Err(_) => new_file_permissions(),
    };
    if let Some(p) = permissions {
        tmp.as_file().set_permissions(p)?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(unix)]
fn new_file_permissions() -> Option<std::fs::Permissions> {
    use std::os::unix::fs::PermissionsExt;
    Some(std::fs::Permissions::from_mode(0o644))
}

#[cfg(not(unix))]
fn new_file_permissions() -> Option<std::fs::Permissions> {
    None
}

/// Why an output cannot be written.
#[derive(Debug)]
pub enum OutputError {
    /// The directory holds files that are not this run's outputs.
    Foreign { dir: PathBuf, holds: String },
    /// An I/O error on `path`.
    Io { path: PathBuf, error: io::Error },
}

impl fmt::Display for OutputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputError::Foreign { dir, holds } => write!(
                f,
                "{}: {holds}; refusing to write into it (choose another --out, or pass --force to write there anyway)",
                dir.display()
            ),
            OutputError::Io { path, error } => write!(f, "{}: {error}", path.display()),
        }
    }
}

impl std::error::Error for OutputError {}

fn io_at(path: &Path) -> impl FnOnce(io::Error) -> OutputError + '_ {
    move |error| OutputError::Io {
        path: path.to_path_buf(),
        error,
    }
}

/// Which run an output directory belongs to: the command and what identifies its outputs
/// (`run`, `scenario default`). A directory is re-used without `--force` only by the same
/// command with the same identity.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Claim {
    pub command: String,
    pub identity: String,
}

impl Claim {
    pub fn new(command: &str, identity: impl Into<String>) -> Self {
        Claim {
            command: command.to_string(),
            identity: identity.into(),
        }
    }
    fn describe(&self) -> String {
        format!("`hil-host {}` ({})", self.command, self.identity)
    }
}

/// An output directory claimed by a command (see the module docs).
#[derive(Debug)]
pub struct OutputDir {
    dir: PathBuf,
    claim: Claim,
    files: Vec<String>,
}

impl OutputDir {
    /// Checks and claims `dir`: creates it when missing; accepts it when it is empty (apart from
    /// temporary left-overs) or its manifest names the same claim; otherwise needs `force`.
    /// Writes the manifest as incomplete, so an interrupted set is recognisable.
    pub fn open(dir: &Path, claim: Claim, force: bool) -> Result<Self, OutputError> {
        if dir.exists() && !dir.is_dir() {
            return Err(OutputError::Io {
                path: dir.to_path_buf(),
                error: io::Error::new(io::ErrorKind::AlreadyExists, "exists and is not a directory"),
            });
        }
        if dir.is_dir() && !force {
            if let Some(holds) = foreign_contents(dir, &claim).map_err(io_at(dir))? {
                return Err(OutputError::Foreign {
                    dir: dir.to_path_buf(),
                    holds,
                });
            }
        }
        std::fs::create_dir_all(dir).map_err(io_at(dir))?;
        let out = OutputDir {
            dir: dir.to_path_buf(),
            claim,
            files: Vec::new(),
        };
        out.write_manifest(false)?;
        Ok(out)
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The path of `name` in the directory.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Writes one file of the set atomically.
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<PathBuf, OutputError> {
        let p = self.path(name);
        write_atomic(&p, bytes).map_err(io_at(&p))?;
        self.record(&p);
        Ok(p)
    }

    /// Removes an earlier run's `name` before the new set is written (a file that must never
    /// sit beside newer files it does not belong to, such as `generate`'s truth.json).
    pub fn remove_old(&self, name: &str) -> Result<(), OutputError> {
        let p = self.path(name);
        check_not_input(&p).map_err(io_at(&p))?;
        match std::fs::remove_file(&p) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => Err(io_at(&p)(e)),
            _ => Ok(()),
        }
    }

    /// Notes a file that a library function wrote into the directory.
    pub fn record(&mut self, path: &Path) {
        let name = path
            .strip_prefix(&self.dir)
            .unwrap_or(path)
            .to_string_lossy()
            .into_owned();
        if !self.files.contains(&name) {
            self.files.push(name);
        }
    }

    /// Completes the set: the manifest, naming the command and every file, written last.
    pub fn finish(self) -> Result<PathBuf, OutputError> {
        self.write_manifest(true)?;
        Ok(self.path(MANIFEST))
    }

    fn write_manifest(&self, complete: bool) -> Result<(), OutputError> {
        let m = json!({
            "tool": "hil-host",
            "version": env!("CARGO_PKG_VERSION"),
            "command": self.claim.command,
            "identity": self.claim.identity,
            "complete": complete,
            "files": self.files,
        });
        let text = serde_json::to_string_pretty(&m).unwrap_or_default() + "\n";
        let p = self.path(MANIFEST);
        write_atomic(&p, text.as_bytes()).map_err(io_at(&p))
    }
}

/// What makes `dir` another run's: `None` when it is empty (temporary left-overs aside) or its
/// manifest names `claim`.
fn foreign_contents(dir: &Path, claim: &Claim) -> io::Result<Option<String>> {
    let mut others = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if !name.starts_with(TMP_PREFIX) {
            others.push(name);
        }
    }
    if others.is_empty() {
        return Ok(None);
    }
    if !others.iter().any(|n| n == MANIFEST) {
        others.sort();
        let shown: Vec<&str> = others.iter().take(3).map(String::as_str).collect();
        let more = if others.len() > 3 { ", ..." } else { "" };
        return Ok(Some(format!(
            "holds files that no hil-host command claims ({}{more}; no {MANIFEST})",
            shown.join(", ")
        )));
    }
    let text = std::fs::read_to_string(dir.join(MANIFEST))?;
    let manifest = serde_json::from_str::<Value>(&text).ok();
    // A run that failed before its first file (a missing input, a log refused) leaves only its
    // incomplete manifest: nothing of it to protect, so any run may take the directory.
    let failed_before_writing = manifest.as_ref().is_some_and(|m| {
        m.get("complete") == Some(&Value::Bool(false))
            && m.get("files").and_then(Value::as_array).is_some_and(|f| f.is_empty())
    });
    if failed_before_writing && others.len() == 1 {
        return Ok(None);
    }
    let owner = manifest.and_then(|m| {
        Some(Claim {
            command: m.get("command")?.as_str()?.to_string(),
            identity: m.get("identity")?.as_str()?.to_string(),
        })
    });
    Ok(match owner {
        Some(o) if o == *claim => None,
        Some(o) => Some(format!(
            "holds the outputs of {}, not of {}",
            o.describe(),
            claim.describe()
        )),
        None => Some(format!("its {MANIFEST} cannot be read")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hil-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn atomic_write_replaces_whole_files_and_leaves_no_temporary() {
        let d = scratch("atomic");
        let p = d.join("a.txt");
        write_atomic(&p, b"old").unwrap();
        write_atomic(&p, b"new content").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new content");
        let names: Vec<_> = std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.txt")]);
        // A write that cannot happen (the directory is gone) leaves nothing behind.
        assert!(write_atomic(&d.join("missing/b.txt"), b"x").is_err());
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn directories_are_claimed_by_their_run() {
        let d = scratch("claim");
        let run = Claim::new("run", "scenario default");
        let mut out = OutputDir::open(&d.join("out"), run.clone(), false).unwrap();
        out.write("evvt.csv", b"t_s\n").unwrap();
        out.finish().unwrap();
        let m: Value = serde_json::from_str(&std::fs::read_to_string(d.join("out").join(MANIFEST)).unwrap()).unwrap();
        assert_eq!(m["complete"], true);
        assert_eq!(m["files"], json!(["evvt.csv"]));
        // The same run again: fine. Another run: refused unless forced.
        OutputDir::open(&d.join("out"), run, false).unwrap();
        let other = OutputDir::open(&d.join("out"), Claim::new("run", "scenario fault-x"), false).unwrap_err();
        assert!(
            other
                .to_string()
                .contains("holds the outputs of `hil-host run` (scenario default)"),
            "{other}"
        );
        OutputDir::open(&d.join("out"), Claim::new("run", "scenario fault-x"), true).unwrap();
        // A directory of someone else's files: refused, naming some of them.
        std::fs::write(d.join("notes.txt"), "mine").unwrap();
        let e = OutputDir::open(&d, Claim::new("run", "scenario default"), false).unwrap_err();
        assert!(
            e.to_string().contains("notes.txt") && e.to_string().contains("--force"),
            "{e}"
        );
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn a_run_that_failed_before_writing_leaves_its_directory_free() {
        let d = scratch("failed");
        // Claimed, then the run fails (no file written, no finish).
        drop(OutputDir::open(&d.join("out"), Claim::new("calibrate", "1 logs"), false).unwrap());
        OutputDir::open(&d.join("out"), Claim::new("calibrate", "9 logs"), false).unwrap();
        // Killed after a file of its set: that file is the run's, so the directory stays claimed.
        let mut out = OutputDir::open(&d.join("out"), Claim::new("calibrate", "9 logs"), false).unwrap();
        out.write("calibration.bin", b"ECAL").unwrap();
        drop(out);
        let e = OutputDir::open(&d.join("out"), Claim::new("calibrate", "2 logs"), false).unwrap_err();
        assert!(
            e.to_string()
                .contains("holds the outputs of `hil-host calibrate` (9 logs)"),
            "{e}"
        );
        std::fs::remove_dir_all(&d).ok();
    }
}
