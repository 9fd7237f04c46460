//! Input/output helpers: `-` means stdin/stdout, and files are written atomically (devices and
//! FIFOs are written straight into; temporary files are removed on failure and on a signal).
//! Directories (a ROS 2 bag) are built the same way in a temporary sibling ([`TempDir`]).

use crate::{Error, Result};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// A human name for a path argument: `stdin`/`stdout` for `-`.
pub fn display_name(path: &Path, stdio: &str) -> String {
    if path == Path::new("-") { stdio.to_string() } else { path.display().to_string() }
}

/// Opens `path` for buffered reading; `-` is stdin.
pub fn open_input(path: &Path) -> Result<Box<dyn BufRead>> {
    if path == Path::new("-") {
        return Ok(Box::new(BufReader::with_capacity(1 << 16, std::io::stdin())));
    }
    let f = File::open(path).map_err(|e| Error::io(path.display().to_string(), &e))?;
    Ok(Box::new(BufReader::with_capacity(1 << 16, f)))
}

/// Reads a whole file (or stdin for `-`) into memory.
pub fn read_all(path: &Path) -> Result<Vec<u8>> {
    let mut buf = Vec::new();
    open_input(path)?.read_to_end(&mut buf).map_err(|e| Error::io(display_name(path, "stdin"), &e))?;
    Ok(buf)
}

/// Writes a file atomically: `write` fills a temporary file in the same directory, which is
/// renamed over `path` only if everything succeeded, so readers never see a half-written file.
/// For `-` the data goes straight to stdout. Anything that exists and is not a regular file (a
/// device such as `/dev/null`, a FIFO, a socket) is written straight into, never replaced; a
/// symbolic link to a regular file keeps the link and replaces the file it points to.
pub fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    write_staged(path, write)?.commit()
}

/// [`write_atomic`] up to the rename: the file is written in full beside `path` and put in
/// place by [`Staged::commit`]. A tool with several outputs stages each and commits them once
/// all of them succeeded, so that a run that fails leaves none of them (stdout and devices are
/// written straight into, as [`write_atomic`] does).
pub fn write_staged<F>(path: &Path, write: F) -> Result<Staged>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    if path == Path::new("-") {
        let stdout = std::io::stdout();
        let mut w = BufWriter::with_capacity(1 << 16, stdout.lock());
        write(&mut w).and_then(|_| w.flush()).map_err(|e| Error::io("stdout", &e))?;
        return Ok(Staged::written("stdout"));
    }
    let name = path.display().to_string();
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => return Err(Error::new(name, "", "is a directory")),
        Ok(m) if !m.is_file() => {
            // A device or FIFO: open it as it is (no create, no truncate) and write into it.
            let result = (|| {
                let f = std::fs::OpenOptions::new().write(true).open(path)?;
                let mut w = BufWriter::with_capacity(1 << 16, f);
                write(&mut w)?;
                w.flush()
            })();
            result.map_err(|e| Error::io(&name, &e))?;
            return Ok(Staged::written(name));
        }
        _ => {}
    }
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path).map_err(|e| Error::io(&name, &e))?,
        _ => path.to_path_buf(),
    };
    let result = (|| {
        let mut tmp = TempFile::create(&target)?;
        let mut w = BufWriter::with_capacity(1 << 16, tmp.file());
        write(&mut w)?;
        w.flush()?;
        drop(w);
        Ok(tmp)
    })();
    let tmp = result.map_err(|e| Error::io(&name, &e))?;
    Ok(Staged { name, pending: Some(Pending::File(tmp)) })
}

/// An output written in full and not yet in place ([`write_staged`]); removed if dropped
/// before [`Staged::commit`].
pub struct Staged {
    name: String,
    pending: Option<Pending>,
}

enum Pending {
    File(TempFile),
    Dir(TempDir),
}

impl Staged {
    /// An output already written where it goes (stdout, a device): nothing to commit.
    fn written(name: impl Into<String>) -> Staged {
        Staged { name: name.into(), pending: None }
    }

    /// A directory built in full in `tmp`, for `name`.
    pub fn dir(name: impl Into<String>, tmp: TempDir) -> Staged {
        Staged { name: name.into(), pending: Some(Pending::Dir(tmp)) }
    }

    /// Puts the output in place. A directory's target that appeared meanwhile is an error.
    pub fn commit(self) -> Result<()> {
        let result = match self.pending {
            None => Ok(()),
            Some(Pending::File(f)) => f.commit(),
            Some(Pending::Dir(d)) => d.commit(),
        };
        result.map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => Error::new(&self.name, "", DIRECTORY_EXISTS),
            _ => Error::io(&self.name, &e),
        })
    }
}

/// Why a directory output (a bag) is refused where its target exists.
pub const DIRECTORY_EXISTS: &str = "already exists (a directory is never overwritten; remove it or choose another)";

/// Checks, before any work, that an output `path` can be created: its directory exists (`-`
/// and existing files or devices pass; whether the directory is writable shows when written).
pub fn check_output_dir(path: &Path) -> Result<()> {
    if path == Path::new("-") || path.exists() {
        return Ok(());
    }
    let dir = parent_dir(path);
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(Error::new(path.display().to_string(), "", format!("{} is not a directory", dir.display()))),
        Err(e) => Err(Error::new(path.display().to_string(), "", format!("directory {}: {e}", dir.display()))),
    }
}

/// Commits every staged output, in order.
pub fn commit_all(staged: impl IntoIterator<Item = Staged>) -> Result<()> {
    staged.into_iter().try_for_each(Staged::commit)
}

/// The marker in every temporary file name: `.NAME.omniscan-tmp-PID`.
const TEMP_MARKER: &str = ".omniscan-tmp-";

/// The temporary sibling used by [`write_atomic`]: hidden, named after the target and the
/// process (`.NAME.omniscan-tmp-PID`), so that a later run can recognise a stale one (its
/// process is gone) and remove it.
pub fn temp_path(path: &Path) -> PathBuf {
    let file = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    parent_dir(path).join(format!(".{file}{TEMP_MARKER}{}", std::process::id()))
}

fn parent_dir(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Temporary files in progress in this process, removed by [`remove_temp_files`].
static TEMP_FILES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
/// Directories already swept of stale temporary files by this process.
static SWEPT_DIRS: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temp_files() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    TEMP_FILES.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes every temporary file this process has in progress. For a signal handler (SIGINT,
/// SIGTERM) just before the process ends: the list stays locked afterwards, so a write that
/// would start a new temporary file waits for the end instead of leaving one behind.
pub fn remove_temp_files() {
    let guard = temp_files();
    for p in guard.iter() {
        remove_temp(p);
    }
    std::mem::forget(guard);
}

/// Removes a temporary file or directory (a directory whose writer is still adding files to
/// it may need a second pass).
fn remove_temp(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            for _ in 0..3 {
                if std::fs::remove_dir_all(path).is_ok() || !path.exists() {
                    break;
                }
            }
        }
        Ok(_) => {
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
}

/// A temporary file that becomes `target` on [`TempFile::commit`]; removed if dropped before,
/// and by [`remove_temp_files`] (a signal) while in progress.
pub struct TempFile {
    path: PathBuf,
    target: PathBuf,
    file: Option<File>,
}

impl TempFile {
    /// Creates the temporary sibling of `target` (see [`temp_path`]), after removing stale
    /// temporary files of dead processes from the directory (once per directory and process).
    pub fn create(target: &Path) -> std::io::Result<TempFile> {
        sweep_stale(parent_dir(target));
        let path = temp_path(target);
        // Created and listed under the lock: a signal handler either sees it or runs first
        // (and then this waits for the end).
        let mut list = temp_files();
        let f = File::create(&path)?;
        list.push(path.clone());
        Ok(TempFile { path, target: target.to_path_buf(), file: Some(f) })
    }

    /// The open temporary file.
    pub fn file(&mut self) -> &mut File {
        self.file.as_mut().expect("open until commit")
    }

    /// Syncs the file and renames it over the target.
    pub fn commit(self) -> std::io::Result<()> {
        self.rename_into_place(true)
    }

    /// Renames the file over the target without syncing it first: readers still never see a
    /// partial file and a crash of this process loses nothing, but a power cut may lose what
    /// the kernel had not written back yet. For files written faster than a sync each allows.
    pub fn commit_unsynced(self) -> std::io::Result<()> {
        self.rename_into_place(false)
    }

    fn rename_into_place(mut self, sync: bool) -> std::io::Result<()> {
        let f = self.file.take().expect("open until commit");
        if sync {
            f.sync_all()?;
        }
        drop(f);
        commit_temp(&self.path, |tmp| std::fs::rename(tmp, &self.target))?;
        self.path = PathBuf::new();
        Ok(())
    }
}

/// Renames a listed temporary into place and unlists it, under the list's lock: after a signal
/// handler has removed the temporaries, nothing more is renamed into place.
fn commit_temp(path: &Path, rename: impl FnOnce(&Path) -> std::io::Result<()>) -> std::io::Result<()> {
    let mut list = temp_files();
    rename(path)?;
    if let Some(k) = list.iter().rposition(|p| p == path) {
        list.swap_remove(k);
    }
    Ok(())
}

/// A temporary directory that becomes `target` on [`TempDir::commit`] (which refuses an existing
/// `target`); removed with its contents if dropped before, and by [`remove_temp_files`] (a
/// signal) while in progress. Named as [`temp_path`] says, and swept as temporary files are.
pub struct TempDir {
    path: PathBuf,
    target: PathBuf,
}

impl TempDir {
    /// Creates the empty temporary sibling of `target`, after sweeping stale temporaries of
    /// dead processes from the parent directory.
    pub fn create(target: &Path) -> std::io::Result<TempDir> {
        sweep_stale(parent_dir(target));
        let path = temp_path(target);
        let mut list = temp_files();
        std::fs::create_dir(&path)?;
        list.push(path.clone());
        Ok(TempDir { path, target: target.to_path_buf() })
    }

    /// The temporary directory, to fill.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the directory to the target; an existing target (even an empty directory) is
    /// an `AlreadyExists` error, never replaced.
    pub fn commit(mut self) -> std::io::Result<()> {
        commit_temp(&self.path, |tmp| rename_no_replace(tmp, &self.target))?;
        self.path = PathBuf::new();
        Ok(())
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !self.path.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.path);
            forget_temp(&self.path);
        }
    }
}

/// `rename(from, to)` that fails if `to` exists (Linux glibc: `renameat2(RENAME_NOREPLACE)`; other
/// systems, or file systems without it: a check just before).
fn rename_no_replace(from: &Path, to: &Path) -> std::io::Result<()> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = |p: &Path| {
            std::ffi::CString::new(p.as_os_str().as_bytes()).map_err(|_| std::io::Error::other("NUL in path"))
        };
        let (a, b) = (c(from)?, c(to)?);
        // SAFETY: two valid C strings; renameat2 reads them only.
        let r =
            unsafe { libc::renameat2(libc::AT_FDCWD, a.as_ptr(), libc::AT_FDCWD, b.as_ptr(), libc::RENAME_NOREPLACE) };
        if r == 0 {
            return Ok(());
        }
        let e = std::io::Error::last_os_error();
        if !matches!(e.raw_os_error(), Some(libc::EINVAL) | Some(libc::ENOSYS)) {
            return Err(e);
        }
    }
    if to.symlink_metadata().is_ok() {
        return Err(std::io::Error::new(std::io::ErrorKind::AlreadyExists, "already exists"));
    }
    std::fs::rename(from, to)
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.path.as_os_str().is_empty() {
            self.file.take();
            let _ = std::fs::remove_file(&self.path);
            forget_temp(&self.path);
        }
    }
}

fn forget_temp(path: &Path) {
    let mut list = temp_files();
    if let Some(k) = list.iter().rposition(|p| p == path) {
        list.swap_remove(k);
    }
}

/// Removes `.NAME.omniscan-tmp-PID` files and directories of processes that no longer run from
/// `dir`, once per directory in this process.
fn sweep_stale(dir: &Path) {
    {
        let mut swept = SWEPT_DIRS.lock().unwrap_or_else(|e| e.into_inner());
        if swept.iter().any(|d| d == dir) {
            return;
        }
        swept.push(dir.to_path_buf());
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = stale_temp_pid(&name.to_string_lossy()) else { continue };
        if pid == std::process::id() || process_alive(pid) {
            continue;
        }
        match entry.file_type() {
            Ok(t) if t.is_file() => {
                let _ = std::fs::remove_file(entry.path());
            }
            // A bag directory a killed run was building (never a symbolic link to one).
            Ok(t) if t.is_dir() => {
                let _ = std::fs::remove_dir_all(entry.path());
            }
            _ => {}
        }
    }
}

/// The process id in a temporary file name `.NAME.omniscan-tmp-PID`, if it is one.
fn stale_temp_pid(name: &str) -> Option<u32> {
    if !name.starts_with('.') {
        return None;
    }
    let k = name.rfind(TEMP_MARKER)?;
    let pid = &name[k + TEMP_MARKER.len()..];
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

#[cfg(unix)]
fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else { return true };
    // Signal 0 checks existence only; EPERM means it exists under another user.
    // SAFETY: kill with signal 0 sends nothing.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

#[cfg(not(unix))]
fn process_alive(_pid: u32) -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.json");
        let r = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("boom"))
        });
        assert!(r.is_err());
        assert!(!path.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        write_atomic(&path, |w| w.write_all(b"ok")).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"ok");
    }

    /// A staged output is nowhere to be seen until committed, and dropped uncommitted it leaves
    /// nothing; an existing file keeps its content until the commit.
    #[test]
    fn staged_outputs_appear_only_when_committed() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
        std::fs::write(&b, b"old").unwrap();
        let staged = [
            write_staged(&a, |w| w.write_all(b"new a")).unwrap(),
            write_staged(&b, |w| w.write_all(b"new b")).unwrap(),
        ];
        assert!(!a.exists() && std::fs::read(&b).unwrap() == b"old");
        drop(staged);
        assert!(!a.exists() && std::fs::read(&b).unwrap() == b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "temporary files left");
        let staged = [
            write_staged(&a, |w| w.write_all(b"new a")).unwrap(),
            write_staged(&b, |w| w.write_all(b"new b")).unwrap(),
        ];
        commit_all(staged).unwrap();
        assert_eq!((std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap()), (b"new a".to_vec(), b"new b".to_vec()));
        assert!(check_output_dir(&dir.path().join("c.txt")).is_ok());
        let err = check_output_dir(&dir.path().join("nodir/c.txt")).unwrap_err().to_string();
        assert!(err.contains("nodir/c.txt") && err.contains("directory"), "{err}");
    }

    #[test]
    fn dev_null_stays_a_device() {
        use std::os::unix::fs::FileTypeExt;
        write_atomic(Path::new("/dev/null"), |w| w.write_all(b"gone")).unwrap();
        assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    }

    #[test]
    fn fifo_is_written_into_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid C string path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_atomic(&fifo, |w| w.write_all(b"through the pipe")).unwrap();
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left");
    }

    #[test]
    fn symlink_is_kept_and_its_file_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.json");
        let link = dir.path().join("link.json");
        std::fs::write(&real, b"old").unwrap();
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_atomic(&link, |w| w.write_all(b"new")).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
    }

    #[test]
    fn directory_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_atomic(dir.path(), |w| w.write_all(b"x")).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
    }

    #[test]
    fn temp_names_are_recognised_and_stale_ones_swept() {
        let name = temp_path(Path::new("d/out.ply"));
        assert_eq!(name, Path::new("d").join(format!(".out.ply.omniscan-tmp-{}", std::process::id())));
        assert_eq!(stale_temp_pid(".frame_3.png.omniscan-tmp-42"), Some(42));
        assert_eq!(stale_temp_pid("frame.omniscan-tmp-42"), None);
        assert_eq!(stale_temp_pid(".frame.omniscan-tmp-4x"), None);

        let dir = tempfile::tempdir().unwrap();
        // A child that has exited: its pid is dead (and not reused this soon).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = dir.path().join(format!(".a.ply.omniscan-tmp-{dead}"));
        let live = dir.path().join(format!(".b.ply.omniscan-tmp-{}", std::process::id()));
        let other = dir.path().join(".c.ply.tmp-1");
        for p in [&stale, &live, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        write_atomic(&dir.path().join("a.ply"), |w| w.write_all(b"ok")).unwrap();
        assert!(!stale.exists(), "a dead process's temporary file is swept");
        assert!(live.exists() && other.exists(), "live and foreign files are left alone");
    }

    #[test]
    fn temp_dirs_are_renamed_into_place_never_over_a_directory_and_swept_when_stale() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("bag");
        let tmp = TempDir::create(&target).unwrap();
        std::fs::write(tmp.path().join("a"), b"x").unwrap();
        let tmp_path = tmp.path().to_path_buf();
        drop(tmp);
        assert!(!tmp_path.exists(), "a dropped temporary directory is removed with its contents");
        // An empty directory appearing meanwhile is not replaced (plain rename would).
        let tmp = TempDir::create(&target).unwrap();
        std::fs::create_dir(&target).unwrap();
        assert_eq!(tmp.commit().unwrap_err().kind(), std::io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "only the existing directory is left");
        std::fs::remove_dir(&target).unwrap();
        let tmp = TempDir::create(&target).unwrap();
        std::fs::write(tmp.path().join("a"), b"x").unwrap();
        tmp.commit().unwrap();
        assert_eq!(std::fs::read(target.join("a")).unwrap(), b"x");

        let other = tempfile::tempdir().unwrap();
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = other.path().join(format!(".bag.omniscan-tmp-{dead}"));
        std::fs::create_dir(&stale).unwrap();
        std::fs::write(stale.join("bag_0.mcap"), b"half").unwrap();
        let real = other.path().join("real");
        std::fs::create_dir(&real).unwrap();
        let link = other.path().join(format!(".l.omniscan-tmp-{dead}"));
        std::os::unix::fs::symlink(&real, &link).unwrap();
        TempDir::create(&other.path().join("b2")).unwrap().commit().unwrap();
        assert!(!stale.exists(), "a dead process's temporary directory is swept");
        assert!(real.exists() && link.symlink_metadata().is_ok(), "a link is not followed or removed");
    }
}
