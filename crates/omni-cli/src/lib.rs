//! The small CLI layer every omniscan binary shares.
//!
//! * [`main`] runs a tool's body and turns its outcome into the Unix conventions: errors are
//!   printed once as `omni-x: error: …` (naming the file and record at fault) with exit code 1;
//!   a closed downstream pipe (`| head`) is a clean exit 0.
//! * [`parse_args`] parses the command line with clap: `--help` and `--version` as clap gives
//!   them, a usage error as one line (what is wrong, then where the help is) with exit code 2;
//!   the tool's own usage errors ([`CliError::usage`]) point to the same help.
//! * [`main`] also removes the temporary files of atomic writes in progress
//!   ([`omni_formats::io::TempFile`]) when SIGINT, SIGTERM or SIGHUP ends the tool, then dies of
//!   that signal as it would have.
//! * [`progress`] gives a progress bar that is drawn only when stderr is a terminal, so pipes
//!   and CI logs stay clean.
//!
//! ```no_run
//! fn main() -> std::process::ExitCode {
//!     omni_cli::main("omni-example", || {
//!         let text = std::fs::read_to_string("in.txt").map_err(|e| format!("in.txt: {e}"))?;
//!         println!("{}", text.len());
//!         Ok(())
//!     })
//! }
//! ```

pub use indicatif::ProgressBar;
use indicatif::{ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::process::ExitCode;

/// Exit code for success (also a closed output pipe).
pub const EXIT_OK: u8 = 0;
/// Exit code for a failure (bad input, I/O error, device error).
pub const EXIT_FAILURE: u8 = 1;
/// Exit code for a usage error (clap uses this too).
pub const EXIT_USAGE: u8 = 2;

/// A tool failure: a one-line message, already naming the file/record at fault.
#[derive(Debug)]
pub struct CliError {
    message: String,
    code: u8,
}

impl CliError {
    /// A failure with exit code 1.
    pub fn new(message: impl Into<String>) -> Self {
        CliError { message: message.into(), code: EXIT_FAILURE }
    }

    /// A usage error (exit code 2), for argument combinations clap cannot check.
    pub fn usage(message: impl Into<String>) -> Self {
        CliError { message: message.into(), code: EXIT_USAGE }
    }

    pub fn message(&self) -> &str {
        &self.message
    }

    /// Whether this is a write to a closed pipe.
    pub fn is_broken_pipe(&self) -> bool {
        self.message.to_ascii_lowercase().contains("broken pipe") || self.message.contains("os error 32")
    }
}

impl<E: std::fmt::Display> From<E> for CliError {
    fn from(e: E) -> Self {
        CliError::new(e.to_string())
    }
}

/// A usage error unless `value` of option `option` (e.g. `--inlier-mm`) is a positive, finite
/// number; the value otherwise.
pub fn positive(option: &str, value: f64) -> CliResult<f64> {
    match value.is_finite() && value > 0.0 {
        true => Ok(value),
        false => Err(CliError::usage(format!("{option} must be positive, got {value}"))),
    }
}

/// Most worker threads a tool starts (`--threads`): far more than any machine's cores, and few
/// enough that a mistyped count cannot tie the machine up in threads.
pub const MAX_THREADS: usize = 1024;

/// `--threads` parsed for clap: 0 (one per core) up to [`MAX_THREADS`].
pub fn parse_threads(text: &str) -> Result<usize, String> {
    let n: usize = text.parse().map_err(|_| format!("expected a whole number of threads, got {text:?}"))?;
    match n <= MAX_THREADS {
        true => Ok(n),
        false => Err(format!("at most {MAX_THREADS} threads, got {n}")),
    }
}

/// A failed write to stdout (a full disk behind `>`, a closed pipe), naming it.
pub fn stdout_error(e: std::io::Error) -> CliError {
    CliError::new(format!("stdout: {e}"))
}

/// The command line, parsed; `--help` and `--version` print and exit 0 as clap does them. A
/// usage error becomes one line with exit code 2 ([`EXIT_USAGE`]): clap's own report spans
/// several (a tip, the usage, a pointer to `--help`), which scripts that read one error line per
/// failure cannot use.
pub fn parse_args<P: clap::Parser>() -> CliResult<P> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    let command = P::command();
    let named = named_command(&command, &args);
    let _ = HELP_COMMAND.set(command_path(&named));
    P::try_parse_from(&args).map_err(|e| usage_error(e, &named))
}

/// The command whose `--help` a usage error points to ([`parse_args`] sets it).
static HELP_COMMAND: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// A usage error's line as printed: ending with the `--help` to read, as clap's own do.
fn with_help_pointer(tool: &str, message: &str) -> String {
    if message.ends_with("--help')") {
        return message.to_string();
    }
    format!("{message} (see '{} --help')", HELP_COMMAND.get().map_or(tool, String::as_str))
}

/// A failed parse as one line ([`parse_args`]), `named` the commands the arguments name; help
/// and version exit.
fn usage_error(e: clap::Error, named: &[&clap::Command]) -> CliError {
    use clap::error::ErrorKind;
    let path = command_path(named);
    let line = match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => e.exit(),
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let last = named.last().expect("the tool itself is named");
            let subcommands: Vec<_> = last.get_subcommands().map(|c| c.get_name()).filter(|n| *n != "help").collect();
            format!("a command is needed: {} (see '{path} --help')", subcommands.join(", "))
        }
        _ => one_line_usage_error(&e.render().to_string(), &path),
    };
    CliError::usage(line)
}

/// The tool and the subcommands the arguments name, e.g. `omni-sim`, `scan`: the help to point to.
fn named_command<'a>(command: &'a clap::Command, args: &[std::ffi::OsString]) -> Vec<&'a clap::Command> {
    let mut path = vec![command];
    for arg in args.iter().skip(1).filter_map(|a| a.to_str()) {
        if let Some(sub) = path.last().and_then(|c| c.find_subcommand(arg)) {
            path.push(sub);
        }
    }
    path
}

/// The commands as typed, e.g. `omni-sim scan`.
fn command_path(named: &[&clap::Command]) -> String {
    named.iter().map(|c| c.get_name()).collect::<Vec<_>>().join(" ")
}

/// Clap's rendered usage error as one line: the error and its details, then where the help of
/// `command` is.
fn one_line_usage_error(rendered: &str, command: &str) -> String {
    let mut lines = rendered.lines().map(str::trim).filter(|l| !l.is_empty());
    let mut message = lines.next().unwrap_or("invalid arguments").trim_start_matches("error: ").to_string();
    // Clap ends its report with the usage and a pointer to --help; the one line ends with its own.
    for line in lines.take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information")) {
        if line.starts_with("tip:") {
            message = format!("{message}; {line}");
        } else {
            let separator = if message.ends_with(':') { " " } else { ", " };
            message = format!("{message}{separator}{line}");
        }
    }
    format!("{message} (see '{command} --help')")
}

/// Creates the output directory of `option` (e.g. `--frames`) with its parents, refusing `-`
/// (a directory of files cannot go to stdout) and a path that is already a file.
pub fn create_output_dir(option: &str, dir: &std::path::Path) -> CliResult {
    if dir == std::path::Path::new("-") {
        return Err(CliError::usage(format!("{option}: names a directory, and `-` (stdout) cannot be one")));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(CliError::new(format!("{}: is a file, not a directory ({option})", dir.display())));
    }
    std::fs::create_dir_all(dir).map_err(|e| CliError::new(format!("{}: {e}", dir.display())))
}

/// The result type of a tool's body.
pub type CliResult<T = ()> = Result<T, CliError>;

/// Runs `body` and maps its result to an exit code (see the crate docs).
pub fn main(tool: &str, body: impl FnOnce() -> CliResult) -> ExitCode {
    keep_freed_frame_buffers();
    remove_temp_files_on_signal();
    match body() {
        Ok(()) => ExitCode::from(EXIT_OK),
        Err(e) if e.is_broken_pipe() => ExitCode::from(EXIT_OK),
        Err(e) => {
            let mut msg = e.message.replace('\n', " ");
            if e.code == EXIT_USAGE {
                msg = with_help_pointer(tool, &msg);
            }
            eprintln!("{tool}: error: {msg}");
            ExitCode::from(e.code)
        }
    }
}

/// Frames' buffers (1–30 MB, a few per frame) are allocated and freed frame after frame. glibc
/// serves such sizes from fresh mappings and unmaps them when freed, so every frame faults in
/// each of its buffers' pages anew: on 3 MB colour frames that took three times the detection's CPU.
/// Kept in the heap instead, freed buffers are reused; what stays resident is the largest set
/// of buffers alive at once, which the tools' bounded frame queues already bound.
fn keep_freed_frame_buffers() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20); // glibc's largest allowed value
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

/// Watches SIGINT, SIGTERM and SIGHUP from a thread: on the first one, removes the temporary
/// files and bag directories of atomic writes in progress and ends the process by that signal's default action (so
/// the shell sees an interrupted tool). After [`stop_on_interrupt`], SIGINT and SIGTERM are
/// left to the tool's orderly stop.
pub fn remove_temp_files_on_signal() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else { return };
        let spawned = std::thread::Builder::new().name("signals".into()).spawn(move || {
            for sig in signals.forever() {
                if sig != SIGHUP && ORDERLY_STOP.load(std::sync::atomic::Ordering::SeqCst) {
                    continue;
                }
                omni_formats::io::remove_temp_files();
                let _ = signal_hook::low_level::emulate_default_handler(sig);
                std::process::exit(128 + sig);
            }
        });
        drop(spawned);
    }
}

/// Set once a tool stops in order on SIGINT/SIGTERM (see [`stop_on_interrupt`]).
static ORDERLY_STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// An orderly stop: SIGINT (Ctrl-C) and SIGTERM raise the returned flag instead of ending the
/// process, so that a long-running tool (a scan, a live publisher) finishes what it holds and
/// still writes its status. SIGHUP keeps its default.
pub fn stop_on_interrupt() -> std::io::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    ORDERLY_STOP.store(true, std::sync::atomic::Ordering::SeqCst);
    #[cfg(unix)]
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, flag.clone())?;
    }
    Ok(flag)
}

/// Whether stderr is an interactive terminal (progress bars are drawn only then).
pub fn stderr_is_terminal() -> bool {
    std::io::stderr().is_terminal()
}

/// A progress bar over `len` items (or a spinner when `len` is unknown), hidden unless stderr
/// is a terminal.
pub fn progress(len: Option<u64>, message: &str) -> ProgressBar {
    let bar = match len {
        Some(n) => ProgressBar::new(n).with_style(
            ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} ({per_sec}, eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("{spinner} {msg} {pos} ({per_sec})")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        ),
    };
    bar.set_message(message.to_string());
    if stderr_is_terminal() {
        bar.set_draw_target(ProgressDrawTarget::stderr());
    } else {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar
}

/// A warning line on stderr in the shared style.
pub fn warn(tool: &str, message: &str) {
    eprintln!("{tool}: warning: {message}");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_counts_are_whole_numbers_up_to_the_limit() {
        assert_eq!(parse_threads("0"), Ok(0));
        assert_eq!(parse_threads("1024"), Ok(MAX_THREADS));
        assert_eq!(parse_threads("100000").unwrap_err(), "at most 1024 threads, got 100000");
        assert!(parse_threads("-1").unwrap_err().contains("whole number"));
    }

    #[test]
    fn broken_pipe_is_recognised() {
        let e: CliError = std::io::Error::from(std::io::ErrorKind::BrokenPipe).into();
        assert!(e.is_broken_pipe());
        assert!(!CliError::new("camera.json: field model: bad").is_broken_pipe());
    }

    #[derive(clap::Parser, Debug)]
    #[command(name = "omni-example")]
    struct Example {
        #[command(subcommand)]
        command: ExampleCommand,
    }

    #[derive(clap::Subcommand, Debug)]
    enum ExampleCommand {
        Fit {
            #[arg(long)]
            camera: String,
            #[arg(long)]
            scanner: String,
            #[arg(long, default_value_t = 1.0)]
            threshold: f64,
        },
    }

    fn usage_line(args: &[&str]) -> String {
        use clap::{CommandFactory, Parser};
        let argv: Vec<std::ffi::OsString> =
            std::iter::once("omni-example").chain(args.iter().copied()).map(Into::into).collect();
        let e = Example::try_parse_from(&argv).unwrap_err();
        let error = usage_error(e, &named_command(&Example::command(), &argv));
        assert_eq!(error.code, EXIT_USAGE);
        error.message
    }

    #[test]
    fn usage_errors_become_one_line_naming_the_argument_and_the_help() {
        assert_eq!(
            usage_line(&["fit", "--camera", "c.json"]),
            "the following required arguments were not provided: --scanner <SCANNER> (see 'omni-example fit --help')"
        );
        assert_eq!(
            usage_line(&["fit", "--camera", "c", "--scanner", "s", "--threshold", "x"]),
            "invalid value 'x' for '--threshold <THRESHOLD>': invalid float literal (see 'omni-example fit --help')"
        );
        let unknown = usage_line(&["fit", "--camera", "c", "--scanner", "s", "--camra"]);
        assert!(unknown.starts_with("unexpected argument '--camra' found; tip: a similar argument exists: '--camera'"));
        assert_eq!(usage_line(&[]), "a command is needed: fit (see 'omni-example --help')");
        let missing = usage_line(&["fit"]);
        assert!(missing.contains("--camera <CAMERA>, --scanner <SCANNER>"), "{missing}");
        for args in [&[][..], &["fit"], &["nope"], &["fit", "--camra"]] {
            let line = usage_line(args);
            assert!(!line.contains('\n') && line.ends_with("--help')"), "{args:?}: {line}");
        }
    }
}
