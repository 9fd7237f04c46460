//! Input/output helpers: `-` means stdin/stdout, and files are written atomically.

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
/// For `-` the data goes straight to stdout.
pub fn write_atomic<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    if path == Path::new("-") {
        let stdout = std::io::stdout();
        let mut w = BufWriter::with_capacity(1 << 16, stdout.lock());
        return write(&mut w).and_then(|_| w.flush()).map_err(|e| Error::io("stdout", &e));
    }
    let name = path.display().to_string();
    let tmp = temp_path(path);
    let result = (|| {
        let f = File::create(&tmp)?;
        let mut w = BufWriter::with_capacity(1 << 16, f);
        write(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(name, &e));
    }
    Ok(())
}

/// The temporary sibling used by [`write_atomic`]: hidden, unique per process.
pub fn temp_path(path: &Path) -> PathBuf {
    let file = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    dir.join(format!(".{file}.tmp-{}", std::process::id()))
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
}
