//! Mutation fuzzing of every omniscan reader on the stable toolchain.
//!
//! `cargo fuzz` (libFuzzer) needs a nightly compiler for its coverage instrumentation; this
//! crate gets most of its value without one. Each [`targets`] entry feeds bytes to a real reader
//! (PLY, stream records, camera/scanner/board/scene files, the controller's line protocol) and
//! accepts only `Ok` or a clean `Err`. [`mutate`] edits seed inputs (bit flips, inserts,
//! deletes, splices, interesting numbers) from a seeded RNG, and [`runner`] reports panics,
//! hangs ([`guard`]'s watchdog) and huge allocations ([`guard`]'s allocator limit) as crashes.
//! Without coverage instrumentation, a new kind of error message (`runner::error_kind`) stands
//! in for new coverage: such inputs join the corpus.
//!
//! * `make fuzz` (or `cargo run --profile fuzz -p omni-fuzz -- --target all --seconds 60`)
//!   fuzzes each target for a set time; crashing inputs go to `target/fuzz-crashes/`
//!   (`--crashes DIR`, named `TARGET-HASH`) and the exit status is 1. The `fuzz` profile keeps
//!   overflow checks and debug assertions on, as cargo-fuzz does.
//! * `tests/seeds.rs` replays the seeds ([`corpus`]), a fixed set of mutations of them and every
//!   file in `crates/omni-fuzz/regressions/` (named `TARGET-…`), so CI keeps found crashes fixed.

pub mod corpus;
pub mod guard;
pub mod mutate;
pub mod runner;
pub mod targets;
