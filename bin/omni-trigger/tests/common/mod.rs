//! Helpers shared by the end-to-end tests: the emulator as a child process and manifest reading.
#![allow(dead_code)]

use omni_formats::stream::{Frame, Record, Status, StreamReader};
use omni_hw::emulator::{TruthRecord, read_truth};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

pub const BIN: &str = env!("CARGO_BIN_EXE_omni-trigger");

/// An emulator child process; killed when dropped.
pub struct Emulator {
    pub child: Child,
    pub port: String,
    pub dir: tempfile::TempDir,
}

impl Emulator {
    pub fn start(args: &[&str]) -> Emulator {
        let dir = tempfile::tempdir().unwrap();
        let mut child = Command::new(BIN)
            .arg("emulate")
            .arg("--frames")
            .arg(dir.path().join("frames"))
            .arg("--truth")
            .arg(dir.path().join("truth.jsonl"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let port = line.trim().to_string();
        assert!(port.starts_with("/dev/"), "emulator printed {line:?}");
        Emulator { child, port, dir }
    }

    pub fn frames(&self) -> PathBuf {
        self.dir.path().join("frames")
    }

    pub fn truth(&self) -> Vec<TruthRecord> {
        let p = self.dir.path().join("truth.jsonl");
        if p.exists() { read_truth(&p).unwrap() } else { vec![] }
    }

    pub fn manifest_path(&self) -> PathBuf {
        self.dir.path().join("scan.jsonl")
    }

    /// A `scan` command against this emulator writing frames into `frames`, manifest to
    /// [`Emulator::manifest_path`].
    pub fn scan_command(&self, frames: &Path, args: &[&str]) -> Command {
        let mut c = Command::new(BIN);
        c.args(["scan", "--port", &self.port, "--frames"]).arg(frames).arg("-o").arg(self.manifest_path()).args(args);
        c
    }

    pub fn scan(&self, args: &[&str]) -> Output {
        Command::new(BIN)
            .args(["scan", "--port", &self.port, "--frames"])
            .arg(self.frames())
            .arg("-o")
            .arg(self.manifest_path())
            .args(args)
            .output()
            .unwrap()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Reads a manifest, checking it is valid JSON Lines: header first, status last, frames between.
pub fn read_manifest(path: &Path) -> (Vec<Frame>, Status) {
    let text = std::fs::read_to_string(path).unwrap();
    let records: Vec<Record> =
        StreamReader::new(text.as_bytes(), "manifest").map(|r| r.unwrap_or_else(|e| panic!("{e}\n{text}"))).collect();
    assert!(matches!(records.first(), Some(Record::Header(_))), "{text}");
    let Some(Record::Status(status)) = records.last().cloned() else { panic!("no final status record:\n{text}") };
    let frames: Vec<Frame> = records[1..records.len() - 1]
        .iter()
        .map(|r| match r {
            Record::Frame(f) => (**f).clone(),
            other => panic!("unexpected record {other:?}"),
        })
        .collect();
    (frames, status)
}

pub fn extra(status: &Status, key: &str) -> u64 {
    status.extra.get(key).and_then(|v| v.as_u64()).unwrap_or_else(|| panic!("status lacks {key}"))
}
