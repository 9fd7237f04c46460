//! The allocation limit: an input asking for more than the limit aborts the process, after the
//! input has been saved to the crash file. The test runs itself again as the child that aborts.

use std::process::Command;

const CHILD: &str = "OMNI_FUZZ_GUARD_CHILD";

/// The child: asks for 64 MiB under a 1 MiB limit while running an input.
fn child(crash_file: &str) {
    omni_fuzz::guard::set_crash_file(Some(std::path::Path::new(crash_file)));
    omni_fuzz::guard::set_limit(1 << 20);
    let input = b"size 67108864".to_vec();
    omni_fuzz::guard::enter(&input);
    let huge: Vec<u8> = Vec::with_capacity(64 << 20);
    std::hint::black_box(&huge);
    omni_fuzz::guard::leave();
}

#[test]
fn a_huge_allocation_aborts_after_saving_the_input() {
    if let Ok(path) = std::env::var(CHILD) {
        return child(&path);
    }
    let dir = std::env::temp_dir().join(format!("omni-fuzz-guard-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let crash = dir.join("crash");
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["a_huge_allocation_aborts_after_saving_the_input", "--exact", "--nocapture"])
        .env(CHILD, &crash)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the child must abort: {stderr}");
    assert!(stderr.contains("allocation above the limit"), "{stderr}");
    assert_eq!(std::fs::read(&crash).unwrap(), b"size 67108864");
    std::fs::remove_dir_all(dir).unwrap();
}
