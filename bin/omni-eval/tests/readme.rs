//! Every command the README shows for real hardware runs (against the virtual controller), so the
//! README cannot rot: scripts/test_readme.sh extracts and runs them.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn readme_hardware_commands_run() {
    let exe = std::env::current_exe().unwrap();
    let bins = exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let work = tempfile::tempdir().unwrap();
    let out =
        Command::new("bash").arg(root.join("scripts/test_readme.sh")).arg(&bins).arg(work.path()).output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "README commands failed:\n{log}");
    assert!(work.path().join("calib/scanner.json").exists() && work.path().join("scan/cloud.ply").exists(), "{log}");
}
