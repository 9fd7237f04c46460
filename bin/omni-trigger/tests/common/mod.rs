//! Helpers shared by the end-to-end tests: the emulator as a child process and manifest reading.
#![allow(dead_code)]

use omni_formats::stream::{Frame, Record, Status, StreamReader};
use omni_hw::emulator::{TruthRecord, read_truth};
use std::collections::HashMap;
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

/// Every paired frame shows exactly the trigger and angle the manifest says (truth from the
/// emulator or the firmware harness: the camera's own record of each trigger), and no frame file is used twice.
pub fn assert_frames_true(frames: &[Frame], truth: &[TruthRecord]) {
    let by_path: HashMap<&str, &TruthRecord> = truth.iter().map(|t| (t.path.as_str(), t)).collect();
    let mut used = std::collections::HashSet::new();
    for f in frames {
        let t = by_path.get(f.path.as_str()).unwrap_or_else(|| panic!("{} not written by the camera", f.path));
        assert_eq!(
            t.trigger_seq, f.seq,
            "{}: paired with trigger {} but shows trigger {}",
            f.path, f.seq, t.trigger_seq
        );
        assert!(
            (t.alpha_deg - f.alpha_deg).abs() < 1e-9,
            "{}: manifest {}° true {}°",
            f.path,
            f.alpha_deg,
            t.alpha_deg
        );
        assert_eq!((t.facet, &t.lasers), (f.facet, &f.lasers), "{}", f.path);
        assert!(used.insert(f.path.clone()), "{} paired twice", f.path);
    }
}
