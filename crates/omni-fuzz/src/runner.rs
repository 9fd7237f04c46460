//! Running targets: one input ([`execute`]), a timed campaign ([`fuzz`]) and the fixed replay
//! of the regression test ([`replay`]).

use crate::corpus::Seed;
use crate::guard;
use crate::mutate::Mutator;
use crate::targets::Target;
use std::cell::RefCell;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Longest input the mutator makes (bytes).
pub const MAX_INPUT: usize = 64 * 1024;
/// Largest corpus a campaign grows to.
const MAX_CORPUS: usize = 4096;

/// What one input did.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Ok,
    /// A clean error, with its message.
    Error(String),
    /// A panic: its message and location.
    Panic(String),
}

thread_local! {
    static IN_TARGET: RefCell<bool> = const { RefCell::new(false) };
    static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Installs a panic hook that records panics inside targets instead of printing them (a
/// campaign meets many); other panics print as usual.
pub fn quiet_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_TARGET.with(|t| *t.borrow()) {
                let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
                LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{}{at}", panic_message(info.payload()))));
            } else {
                default(info);
            }
        }));
    });
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(non-string panic)".into())
}

/// Runs one input through `target`, turning a panic into [`Outcome::Panic`].
pub fn execute(target: &Target, input: &[u8]) -> Outcome {
    quiet_panics();
    IN_TARGET.with(|t| *t.borrow_mut() = true);
    guard::enter(input);
    let result = std::panic::catch_unwind(|| (target.run)(input));
    guard::leave();
    IN_TARGET.with(|t| *t.borrow_mut() = false);
    match result {
        Ok(Ok(())) => Outcome::Ok,
        Ok(Err(m)) => Outcome::Error(m),
        Err(payload) => {
            Outcome::Panic(LAST_PANIC.with(|p| p.borrow_mut().take()).unwrap_or_else(|| panic_message(&*payload)))
        }
    }
}

/// The kind of an error message, standing in for coverage (a new kind joins the corpus): the
/// words of its first line that do not echo `input` (field names, quoted values, lines: words
/// found in the input or holding other than letters, `_`, `.`, `-`), a run of numbers as one
/// `#`; at most 16 words. "line 3: bad \"x\"" and "line 4: bad \"y\"" are one kind.
pub fn error_kind(message: &str, input: &[u8]) -> String {
    let text = String::from_utf8_lossy(input);
    let line = message.lines().next().unwrap_or("");
    let words = line.split(|c: char| c.is_whitespace() || "\"'`:,;()[]{}".contains(c)).filter(|w| !w.is_empty());
    let kept = words.filter_map(|w| {
        if w.bytes().all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b)) && w.bytes().any(|b| b.is_ascii_digit()) {
            Some("#")
        } else if text.contains(w) || !w.chars().all(|c| c.is_ascii_alphabetic() || "_.-".contains(c)) {
            None
        } else {
            Some(w)
        }
    });
    let mut out: Vec<&str> = Vec::new();
    for w in kept {
        if !(w == "#" && out.last() == Some(&"#")) {
            out.push(w);
        }
    }
    out.truncate(16);
    out.join(" ")
}

/// Where a panic happened (its message's last ` at FILE:LINE`), which tells crashes apart.
fn panic_site(message: &str) -> &str {
    message.rsplit(" at ").next().unwrap_or(message)
}

/// A crashing input.
#[derive(Debug, Clone)]
pub struct Crash {
    pub message: String,
    pub input: Vec<u8>,
    /// Where it was saved, if it was.
    pub saved: Option<PathBuf>,
}

/// The figures of one target's campaign.
#[derive(Debug, Clone)]
pub struct Report {
    pub target: &'static str,
    pub seconds: f64,
    pub execs: u64,
    pub seeds: usize,
    /// Inputs kept for giving a new kind of error (the corpus' growth).
    pub corpus: usize,
    pub error_kinds: usize,
    /// One crash per place that panicked.
    pub crashes: Vec<Crash>,
}

impl Report {
    pub fn execs_per_second(&self) -> f64 {
        self.execs as f64 / self.seconds.max(1e-9)
    }
}

/// How a campaign runs.
#[derive(Debug, Clone)]
pub struct Options {
    pub duration: Duration,
    pub seed: u64,
    /// Where crashing inputs are saved (`None`: kept in the report only).
    pub crashes_dir: Option<PathBuf>,
}

/// State of one campaign.
struct Campaign<'a> {
    target: &'a Target,
    corpus: Vec<Vec<u8>>,
    kinds: HashSet<String>,
    crashes: Vec<Crash>,
    panics_seen: HashSet<String>,
    crashes_dir: Option<PathBuf>,
    execs: u64,
}

impl Campaign<'_> {
    /// Runs `input`; a new kind of error or a crash is remembered. Returns whether it was new.
    fn run(&mut self, input: &[u8]) -> bool {
        self.execs += 1;
        match execute(self.target, input) {
            Outcome::Ok => self.kinds.insert("ok".into()),
            Outcome::Error(m) => self.kinds.insert(error_kind(&m, input)),
            Outcome::Panic(m) => {
                if self.panics_seen.insert(panic_site(&m).to_string()) {
                    let saved = self.crashes_dir.as_deref().and_then(|d| save_crash(d, self.target.name, input));
                    self.crashes.push(Crash { message: m, input: input.to_vec(), saved });
                }
                false
            }
        }
    }
}

/// Saves a crashing input as `DIR/<target>-<hash>`, the name `regressions/` expects.
fn save_crash(dir: &Path, target: &str, input: &[u8]) -> Option<PathBuf> {
    std::fs::create_dir_all(dir).ok()?;
    let hash = input.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
    let path = dir.join(format!("{target}-{hash:016x}"));
    std::fs::write(&path, input).ok()?;
    Some(path)
}

/// Fuzzes `target` from `seeds` for the set time: every seed once, then mutations of the
/// corpus, which grows by every input that gives a new kind of error.
pub fn fuzz(target: &'static Target, seeds: &[Seed], options: &Options) -> Report {
    let start = Instant::now();
    let mut campaign = Campaign {
        target,
        corpus: seeds.iter().map(|s| s.bytes.clone()).collect(),
        kinds: HashSet::new(),
        crashes: Vec::new(),
        panics_seen: HashSet::new(),
        crashes_dir: options.crashes_dir.clone(),
        execs: 0,
    };
    if campaign.corpus.is_empty() {
        campaign.corpus.push(Vec::new());
    }
    guard::set_crash_file(options.crashes_dir.as_ref().map(|d| d.join(format!("{}-running", target.name))).as_deref());
    for s in seeds {
        campaign.run(&s.bytes);
    }
    let mut mutator = Mutator::new(options.seed ^ omni_geom::rng::mix(target.name.len() as u64), MAX_INPUT);
    let mut input = Vec::with_capacity(MAX_INPUT + 64);
    while start.elapsed() < options.duration {
        for _ in 0..32 {
            let base = mutator.below(campaign.corpus.len());
            let other = mutator.below(campaign.corpus.len());
            mutator.mutate(&campaign.corpus[base], &campaign.corpus[other], &mut input);
            if campaign.run(&input) && campaign.corpus.len() < MAX_CORPUS {
                campaign.corpus.push(input.clone());
            }
        }
    }
    guard::set_crash_file(None);
    Report {
        target: target.name,
        seconds: start.elapsed().as_secs_f64(),
        execs: campaign.execs,
        seeds: seeds.len(),
        corpus: campaign.corpus.len(),
        error_kinds: campaign.kinds.len(),
        crashes: campaign.crashes,
    }
}

/// The regression test's fixed run: every seed, then `mutations` mutations of the seeds (round
/// robin, RNG seeded with `seed`); returns the crashes with the input's origin.
pub fn replay(target: &Target, seeds: &[Seed], mutations: usize, seed: u64) -> Vec<(String, Outcome)> {
    let mut crashes = Vec::new();
    for s in seeds {
        if let o @ Outcome::Panic(_) = execute(target, &s.bytes) {
            crashes.push((s.name.clone(), o));
        }
    }
    if seeds.is_empty() {
        return crashes;
    }
    let mut mutator = Mutator::new(seed, MAX_INPUT);
    let mut input = Vec::with_capacity(MAX_INPUT + 64);
    for i in 0..mutations {
        let base = &seeds[i % seeds.len()];
        let other = &seeds[mutator.below(seeds.len())];
        mutator.mutate(&base.bytes, &other.bytes, &mut input);
        if let o @ Outcome::Panic(_) = execute(target, &input) {
            crashes.push((format!("mutation {i} of {} ({:?})", base.name, String::from_utf8_lossy(&input)), o));
        }
    }
    crashes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panics(data: &[u8]) -> Result<(), String> {
        if data.first() == Some(&b'!') { panic!("boom") } else { Err(format!("line {}", data.len())) }
    }

    const PANICS: Target = Target { name: "test", about: "panics on '!'", run: panics };

    #[test]
    fn a_panic_is_an_outcome_with_its_location_and_errors_are_kinds() {
        match execute(&PANICS, b"!x") {
            Outcome::Panic(m) => assert!(m.starts_with("boom at ") && m.contains("runner.rs"), "{m}"),
            other => panic!("{other:?}"),
        }
        assert_eq!(execute(&PANICS, b"abc"), Outcome::Error("line 3".into()));
        assert_eq!(
            error_kind("line 12, field inner_rows: bad \"x1\"\nmore", b"{\"inner_rows\": x1}"),
            "line # field bad"
        );
        assert_eq!(error_kind("line 3: bad", b"q"), error_kind("line 4: bad", b"q"));
        assert_eq!(panic_site("boom at src/a.rs:3"), "src/a.rs:3");
    }

    #[test]
    fn a_campaign_finds_the_crash_and_saves_it() {
        let dir = std::env::temp_dir().join(format!("omni-fuzz-test-{}", std::process::id()));
        let seeds = [Seed { name: "s".into(), bytes: b"abc".to_vec() }];
        let options = Options { duration: Duration::from_millis(300), seed: 3, crashes_dir: Some(dir.clone()) };
        let report = fuzz(&PANICS, &seeds, &options);
        assert_eq!(report.crashes.len(), 1, "{report:?}");
        let saved = report.crashes[0].saved.as_ref().unwrap();
        assert_eq!(std::fs::read(saved).unwrap()[0], b'!');
        assert!(saved.file_name().unwrap().to_string_lossy().starts_with("test-"));
        std::fs::remove_dir_all(dir).unwrap();
    }
}
