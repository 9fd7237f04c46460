//! `omni-fuzz`: mutation fuzzing of the omniscan readers for a set time per target.

use clap::Parser;
use omni_fuzz::runner::{self, Options, Report};
use omni_fuzz::{corpus, guard, targets};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// Fuzzes the omniscan readers (stable toolchain, no libFuzzer); exits 1 on a crash.
///
/// Example: omni-fuzz --target all --seconds 60 --crashes target/fuzz-crashes
#[derive(Parser)]
#[command(name = "omni-fuzz", version)]
struct Args {
    /// Target to fuzz (ply, stream, camera, scanner, board, scene, controller) or `all`.
    #[arg(long, default_value = "all")]
    target: String,
    /// Seconds per target.
    #[arg(long, default_value_t = 60.0)]
    seconds: f64,
    /// RNG seed: the same seed and duration replay the same inputs.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Directory for crashing inputs (copy one to crates/omni-fuzz/regressions/ to keep it).
    #[arg(long, default_value = "target/fuzz-crashes")]
    crashes: PathBuf,
    /// Seconds one input may run before it counts as a hang.
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Largest single allocation an input may cause (MiB).
    #[arg(long, default_value_t = 512)]
    max_alloc_mib: usize,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let chosen: Vec<&'static targets::Target> = if args.target == "all" {
        targets::TARGETS.iter().collect()
    } else if let Some(t) = targets::find(&args.target) {
        vec![t]
    } else {
        let names: Vec<&str> = targets::TARGETS.iter().map(|t| t.name).collect();
        eprintln!("omni-fuzz: --target: unknown target {:?} (known: {}, all)", args.target, names.join(", "));
        return ExitCode::from(2);
    };
    if !(args.seconds.is_finite() && args.seconds >= 0.0 && args.timeout.is_finite() && args.timeout > 0.0) {
        eprintln!("omni-fuzz: --seconds must be non-negative and --timeout positive");
        return ExitCode::from(2);
    }
    guard::set_limit(args.max_alloc_mib.saturating_mul(1 << 20));
    guard::start_watchdog(Duration::from_secs_f64(args.timeout));
    let options =
        Options { duration: Duration::from_secs_f64(args.seconds), seed: args.seed, crashes_dir: Some(args.crashes) };
    println!(
        "{:<11} {:>7} {:>10} {:>9} {:>6} {:>7} {:>7} {:>8}",
        "target", "seconds", "execs", "execs/s", "seeds", "corpus", "kinds", "crashes"
    );
    let mut crashed = false;
    for target in chosen {
        let report = runner::fuzz(target, &corpus::seeds(target.name), &options);
        print_report(&report);
        crashed |= !report.crashes.is_empty();
    }
    if crashed { ExitCode::from(1) } else { ExitCode::SUCCESS }
}

/// One table row (`kinds`: distinct kinds of clean error, see `runner::error_kind`), then one
/// line per crash.
fn print_report(r: &Report) {
    println!(
        "{:<11} {:>7.1} {:>10} {:>9.0} {:>6} {:>7} {:>7} {:>8}",
        r.target,
        r.seconds,
        r.execs,
        r.execs_per_second(),
        r.seeds,
        r.corpus,
        r.error_kinds,
        r.crashes.len()
    );
    for c in &r.crashes {
        let at = c.saved.as_ref().map(|p| format!(" (saved to {})", p.display())).unwrap_or_default();
        println!("  crash: {}{at}", c.message);
    }
}
