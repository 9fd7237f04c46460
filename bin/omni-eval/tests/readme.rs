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
    // calibrate.sh keeps the tools' reports (written to stderr) beside the calibration.
    let report = |f: &str| std::fs::read_to_string(work.path().join("calib").join(f)).unwrap_or_default();
    assert!(report("receiver.txt").contains("corners"), "receiver.txt: {}", report("receiver.txt"));
    assert!(report("planes.txt").contains("model residual RMS"), "planes.txt: {}", report("planes.txt"));
}

#[test]
fn readme_first_screen_says_where_the_tools_are() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let first_screen: String = readme.lines().take(30).collect::<Vec<_>>().join("\n");
    for needle in ["target/release", "cargo install --path bin/", "PATH", "rustup component add rustfmt clippy"] {
        assert!(first_screen.contains(needle), "the README's first 30 lines do not say {needle:?}");
    }
}

#[test]
fn make_test_says_how_to_install_rustfmt_and_clippy() {
    use std::os::unix::fs::PermissionsExt;
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = tempfile::tempdir().unwrap();
    for missing in ["fmt", "clippy"] {
        // A cargo whose `fmt` or `clippy` subcommand is not installed.
        let fake = dir.path().join(format!("cargo-without-{missing}"));
        std::fs::write(&fake, format!("#!/bin/sh\n[ \"$1\" = {missing} ] && exit 101\nexit 0\n")).unwrap();
        std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
        let out = Command::new("make")
            .current_dir(&root)
            .arg("-s")
            .arg("tools")
            .arg(format!("CARGO={}", fake.display()))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{missing}: {err}");
        assert!(err.contains("rustup component add rustfmt clippy"), "{missing}: {err}");
    }
    let out = Command::new("make").current_dir(&root).args(["-s", "tools"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Every `--help` example is one line, whatever the terminal's width, so that copy and paste
/// gives the whole command (a wrapped example continues on a line that starts with its next
/// argument instead of a new command).
#[test]
fn help_examples_stay_on_one_line() {
    let exe = std::env::current_exe().unwrap();
    let bins = exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf();
    let tools = [
        ("omni-calib-plane", vec![]),
        ("omni-calib-receiver", vec![]),
        ("omni-eval", vec!["budget"]),
        ("omni-merge", vec![]),
        ("omni-ridge", vec![]),
        ("omni-sim", vec![]),
        ("omni-sim", vec!["rig"]),
        ("omni-triangulate", vec![]),
        ("omni-trigger", vec!["scan"]),
    ];
    for (tool, sub) in tools {
        let out = Command::new(bins.join(tool)).args(&sub).arg("--help").env("COLUMNS", "60").output().unwrap();
        let help = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success() && help.contains("omni-"), "{tool} {sub:?} --help failed");
        let lines: Vec<&str> = help.lines().collect();
        let examples = lines.iter().filter(|l| l.trim_start().starts_with("omni-")).count();
        assert!(examples > 0, "{tool} {sub:?}: no example in --help");
        for pair in lines.windows(2) {
            let (line, next) = (pair[0].trim_start(), pair[1]);
            let continued = next.starts_with("  ")
                && !next.trim_start().starts_with("omni-")
                && next.trim_start().chars().next().is_some_and(|c| c.is_ascii_lowercase() || c == '-');
            assert!(
                !(line.starts_with("omni-") && continued),
                "{tool} {sub:?}: the example {line:?} goes on in {next:?}"
            );
        }
    }
}

/// A usage error is one line on stderr, exit code 2, naming what is wrong and the help to read,
/// in every tool and subcommand: unknown options, bad values, missing arguments and commands.
#[test]
fn usage_errors_are_one_line_with_exit_code_2() {
    let exe = std::env::current_exe().unwrap();
    let bins = exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf();
    let cases: &[(&str, &[&str], &str)] = &[
        ("omni-calib-plane", &["fixed", "--bogus"], "'--bogus'"),
        ("omni-calib-receiver", &["--bogus"], "'--bogus'"),
        ("omni-eval", &[], "a command is needed: "),
        ("omni-eval", &["compare"], "--scene"),
        ("omni-live", &["--foxglove"], "--foxglove"),
        ("omni-merge", &["--voxel", "x"], "'x'"),
        ("omni-ridge", &["--threshold", "x"], "--threshold"),
        ("omni-sim", &["scan", "--camra", "c.json"], "'--camera'"),
        ("omni-triangulate", &["--bogus"], "'--bogus'"),
        ("omni-trigger", &[], "a command is needed: "),
    ];
    for (tool, args, names) in cases {
        let out = Command::new(bins.join(tool)).args(*args).stdin(std::process::Stdio::null()).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{tool} {args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{tool} {args:?}: {err}");
        assert!(err.starts_with(&format!("{tool}: error: ")) && err.contains(names), "{tool} {args:?}: {err}");
        assert!(err.trim_end().ends_with("--help')"), "{tool} {args:?}: {err}");
    }
}
