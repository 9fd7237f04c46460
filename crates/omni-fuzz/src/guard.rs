//! What `catch_unwind` cannot catch: huge allocations and hangs.
//!
//! * [`LimitAlloc`], the global allocator of every program linking this crate, refuses any
//!   single allocation above [`set_limit`] bytes (a reader trusting a size from its input): it
//!   saves the input being run to the crash file and lets Rust abort with "memory allocation of
//!   N bytes failed". Saving uses raw `libc` calls, since the allocator must not allocate.
//! * [`start_watchdog`] ends the process (exit 1) when one input runs longer than its timeout,
//!   after saving that input.
//!
//! The runner marks each input with [`enter`]/[`leave`]; the input buffer must stay alive
//! and unmoved in between, which it does since the target borrows it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::ffi::CString;
use std::sync::Mutex;
use std::sync::atomic::{AtomicPtr, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

static LIMIT: AtomicUsize = AtomicUsize::new(usize::MAX);
static INPUT_PTR: AtomicPtr<u8> = AtomicPtr::new(std::ptr::null_mut());
static INPUT_LEN: AtomicUsize = AtomicUsize::new(0);
/// Milliseconds since [`epoch`] when the current input started, 0 when none is running.
static STARTED_MS: AtomicU64 = AtomicU64::new(0);
static CRASH_FILE: Mutex<Option<CString>> = Mutex::new(None);

/// The global allocator: the system's, with a per-allocation size limit.
pub struct LimitAlloc;

#[global_allocator]
static GLOBAL: LimitAlloc = LimitAlloc;

// SAFETY: every call is forwarded to `System` unchanged, or answered with null (allocation
// failure), which the `GlobalAlloc` contract allows.
unsafe impl GlobalAlloc for LimitAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if refuse(layout.size()) { std::ptr::null_mut() } else { unsafe { System.alloc(layout) } }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if refuse(layout.size()) { std::ptr::null_mut() } else { unsafe { System.alloc_zeroed(layout) } }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if refuse(new_size) { std::ptr::null_mut() } else { unsafe { System.realloc(ptr, layout, new_size) } }
    }
}

/// Whether an allocation of `size` bytes is over the limit; if so, the input is saved first.
fn refuse(size: usize) -> bool {
    if size <= LIMIT.load(Ordering::Relaxed) {
        return false;
    }
    write_stderr(b"omni-fuzz: an input asked for an allocation above the limit (a size read from the input?)\n");
    save_input_raw();
    true
}

/// Refuses single allocations above `bytes` from now on.
pub fn set_limit(bytes: usize) {
    LIMIT.store(bytes, Ordering::Relaxed);
}

/// Where the allocator and the watchdog save the input that crashed (`None`: nowhere).
pub fn set_crash_file(path: Option<&std::path::Path>) {
    let c = path.and_then(|p| CString::new(p.as_os_str().as_encoded_bytes()).ok());
    *CRASH_FILE.lock().unwrap_or_else(|e| e.into_inner()) = c;
}

/// Marks `input` as running.
pub fn enter(input: &[u8]) {
    INPUT_PTR.store(input.as_ptr().cast_mut(), Ordering::SeqCst);
    INPUT_LEN.store(input.len(), Ordering::SeqCst);
    STARTED_MS.store(now_ms().max(1), Ordering::SeqCst);
}

/// Marks the input as done.
pub fn leave() {
    STARTED_MS.store(0, Ordering::SeqCst);
    INPUT_PTR.store(std::ptr::null_mut(), Ordering::SeqCst);
    INPUT_LEN.store(0, Ordering::SeqCst);
}

fn epoch() -> Instant {
    static EPOCH: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

fn now_ms() -> u64 {
    epoch().elapsed().as_millis() as u64
}

/// Starts a thread that ends the process (exit 1) when one input runs longer than `timeout`.
pub fn start_watchdog(timeout: Duration) {
    epoch();
    std::thread::spawn(move || {
        loop {
            std::thread::sleep(Duration::from_millis(100));
            let started = STARTED_MS.load(Ordering::SeqCst);
            if started != 0 && now_ms().saturating_sub(started) > timeout.as_millis() as u64 {
                eprintln!("omni-fuzz: an input has run for more than {timeout:?} (a hang)");
                save_input_raw();
                std::process::exit(1);
            }
        }
    });
}

/// Writes the running input to the crash file with raw system calls (no allocation: this runs
/// inside the allocator).
fn save_input_raw() {
    let (ptr, len) = (INPUT_PTR.load(Ordering::SeqCst), INPUT_LEN.load(Ordering::SeqCst));
    let Ok(guard) = CRASH_FILE.try_lock() else { return };
    let Some(path) = guard.as_ref() else { return };
    if ptr.is_null() {
        return;
    }
    // SAFETY: `path` is a valid C string; `ptr..ptr+len` is the running input, alive until
    // `leave` (the caller is the running input's own thread, or the watchdog while it hangs).
    unsafe {
        let fd = libc::open(path.as_ptr(), libc::O_WRONLY | libc::O_CREAT | libc::O_TRUNC, 0o644);
        if fd >= 0 {
            libc::write(fd, ptr.cast(), len);
            libc::close(fd);
            write_stderr(b"omni-fuzz: input saved to ");
            write_stderr(path.as_bytes());
            write_stderr(b"\n");
        }
    }
}

fn write_stderr(bytes: &[u8]) {
    // SAFETY: writes `bytes` to file descriptor 2; no memory is touched but `bytes`.
    unsafe {
        libc::write(2, bytes.as_ptr().cast(), bytes.len());
    }
}
