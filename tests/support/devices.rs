//! Test support shared by the tools' integration tests (included with `#[path]`): outputs that
//! are devices or FIFOs must be written into, never replaced.

use std::path::Path;
use std::process::{Command, Output};

/// Runs the tool with its output at `/dev/null` and at a FIFO (read by a thread): both must be
/// written into, not replaced by a regular file. Returns what came through the FIFO.
pub fn writes_into_devices(dir: &Path, run_to: impl Fn(&str) -> Output) -> Vec<u8> {
    use std::os::unix::fs::FileTypeExt;
    let out = run_to("/dev/null");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(), "/dev/null was replaced");
    let fifo = dir.join("out.fifo");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = fifo.clone();
    std::thread::spawn(move || tx.send(std::fs::read(reader).unwrap()));
    let out = run_to(fifo.to_str().unwrap());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo(), "the FIFO was replaced");
    let bytes = rx.recv_timeout(std::time::Duration::from_secs(20)).expect("nothing was written into the FIFO");
    let litter: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("tmp"))
        .collect();
    assert!(litter.is_empty(), "temporary files left: {litter:?}");
    bytes
}
