//! CI's fuzzing: every seed, a fixed set of mutations of the seeds and every saved regression
//! input, through every target. Only `Ok` or a clean error is acceptable; a panic fails the
//! test and names the input. Deterministic (fixed RNG seed), a few seconds in all.

use omni_fuzz::corpus::{self, Seed};
use omni_fuzz::runner::{self, Outcome};
use omni_fuzz::targets::{TARGETS, Target};

/// Mutations replayed per target.
const MUTATIONS: usize = 1000;

fn describe(crashes: &[(String, Outcome)]) -> String {
    crashes.iter().map(|(input, o)| format!("  {input}: {o:?}")).collect::<Vec<_>>().join("\n")
}

/// A seed that the reader refuses tests little: every seed not named `bad-…` must be accepted.
fn assert_seeds_are_accepted(target: &Target, seeds: &[Seed]) {
    for s in seeds.iter().filter(|s| !s.name.rsplit('/').next().unwrap_or("").starts_with("bad-")) {
        assert_eq!(runner::execute(target, &s.bytes), Outcome::Ok, "{}: seed {} is refused", target.name, s.name);
    }
}

#[test]
fn every_target_has_seeds_and_accepts_them() {
    for target in TARGETS {
        let seeds = corpus::seeds(target.name);
        assert!(!seeds.is_empty(), "{} has no seeds", target.name);
        assert_seeds_are_accepted(target, &seeds);
    }
}

#[test]
fn seeds_and_their_mutations_do_not_crash() {
    omni_fuzz::guard::set_limit(1 << 30);
    let mut failures = Vec::new();
    for (k, target) in TARGETS.iter().enumerate() {
        let crashes = runner::replay(target, &corpus::seeds(target.name), MUTATIONS, 0x5eed + k as u64);
        if !crashes.is_empty() {
            failures.push(format!("{}:\n{}", target.name, describe(&crashes)));
        }
    }
    assert!(failures.is_empty(), "crashes:\n{}", failures.join("\n"));
}

#[test]
fn saved_regressions_do_not_crash() {
    for target in TARGETS {
        let crashes = runner::replay(target, &corpus::regressions(target.name), 0, 0);
        assert!(crashes.is_empty(), "{}:\n{}", target.name, describe(&crashes));
    }
}

#[test]
fn every_regression_file_names_a_target() {
    let dir = corpus::crate_dir().join("regressions");
    for entry in std::fs::read_dir(&dir).unwrap().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || name == "README.md" {
            continue;
        }
        let target = name.split('-').next().unwrap_or("");
        assert!(omni_fuzz::targets::find(target).is_some(), "regressions/{name}: no target {target:?}");
    }
}
