//! The streaming pipeline: a reader thread, a pool of frame workers and an in-order writer.
//!
//! At most `window` records are in flight between reading and writing (a token is taken per
//! record read and returned per record written), so memory stays bounded however long the
//! stream is, while frames are processed in parallel and written in input order, each flushed
//! at once.

use omni_cli::{CliError, CliResult};
use omni_formats::stream::{FrameError, Record, StreamReader, StreamWriter};
use omni_model::CameraModel;
use omni_vision::colour::ColourSpec;
use omni_vision::image_io::{DecodedGray, GrayImage, write_rgb_png};
use omni_vision::stripe::{self, RidgeDetector, RidgeParams, SearchRegion};
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex, OnceLock};

/// Everything the workers need.
pub struct Config {
    pub params: RidgeParams,
    pub camera: Option<Box<dyn CameraModel>>,
    pub overlay: Option<PathBuf>,
    pub keep_going: bool,
    /// Write the arrays in binary (stream version 2).
    pub binary: bool,
    pub threads: usize,
    /// Appended to the header's producers.
    pub producer: String,
    /// A stream without its final status record is an error, not a warning.
    pub strict: bool,
    /// Subtracted from every laser frame that has no laser-off frame of its own.
    pub static_ambient: Option<GrayImage>,
    /// How colour and Bayer frames become the detector's grey image.
    pub colour: ColourSpec,
    /// The user's ROI or mask, within the camera's annulus (or the whole frame).
    pub region: Option<SearchRegion>,
}

/// The status record's count of laser frames in which no stripe was found.
pub const FRAMES_WITHOUT_STRIPE: &str = "frames_without_stripe";

/// The prefix of the error returned after a `--keep-going` run with failed frames.
const KEEP_GOING_SUMMARY: &str = "frames failed";

/// Whether `e` is the end-of-run summary of a `--keep-going` run (the output is complete).
pub fn is_keep_going_summary(e: &CliError) -> bool {
    e.message().contains(KEEP_GOING_SUMMARY)
}

/// A record on its way through the pipe: its position, and the frames directory in force.
struct Job {
    index: usize,
    record: Record,
    frames_dir: Option<String>,
}

/// A worker's answer: the finished record, or a failure naming the frame.
type Outcome = (usize, Result<Record, FrameError>);

/// Frames are checked against the camera's size; without a camera the first frame fixes the
/// size and the whole frame is searched.
struct Detectors {
    params: RidgeParams,
    camera: Option<RidgeDetector>,
    region: Option<SearchRegion>,
    from_first_frame: OnceLock<Result<RidgeDetector, String>>,
    /// Laser-off frames, decoded once for all the frames that share them.
    laser_off: stripe::LaserOffCache,
    static_ambient: Option<DecodedGray>,
    along: AlongStripeTally,
    /// How frames are read, and whether the hint about colour read as luma was given.
    colour: ColourSpec,
    /// For a mosaic read at its sites: the frame pixel of the first site, and the detector for
    /// the half-size frames it reads (built from the frame's detector when first needed).
    sites: Option<((u32, u32), OnceLock<RidgeDetector>)>,
    luma_hint: std::sync::atomic::AtomicBool,
}

/// The points `--along-stripe` kept and refused over the run (stripes shorter than its window).
#[derive(Default)]
struct AlongStripeTally {
    kept: AtomicUsize,
    refused: AtomicUsize,
    /// The longest stripe span seen (px), as f64 bits (non-negative floats order as their bits).
    longest_bits: AtomicU64,
}

impl AlongStripeTally {
    /// The fit needs `window` px of stripe ([`RidgeParams::along_stripe_window_px`]); refusing
    /// stripes shorter than it is the user's business to hear about, and a run where it refused
    /// everything is an error.
    fn verdict(&self, along_px: f64, window: f64) -> CliResult {
        let (kept, refused) = (self.kept.load(Ordering::Relaxed), self.refused.load(Ordering::Relaxed));
        if refused == 0 {
            return Ok(());
        }
        let longest = f64::from_bits(self.longest_bits.load(Ordering::Relaxed));
        if kept == 0 {
            return Err(CliError::new(format!(
                "--along-stripe {along_px} px fits over {window} px of stripe, longer than every stripe found \
                 (the longest spans {longest:.1} px end to end): nothing was measured; use --along-stripe {} or less",
                (longest / 2.0).floor()
            )));
        }
        omni_cli::warn(
            "omni-ridge",
            &format!(
                "--along-stripe {along_px} px: {refused} of {} points refused, on stripes shorter than its {window} px window",
                kept + refused
            ),
        );
        Ok(())
    }
}

impl Detectors {
    fn for_size(&self, width: u32, height: u32) -> Result<(&RidgeDetector, &'static str), String> {
        match &self.camera {
            Some(d) => Ok((d, "the camera's image")),
            None => {
                let detector = self.from_first_frame.get_or_init(|| {
                    let whole = RidgeDetector::whole_frame(width, height, self.params);
                    match &self.region {
                        Some(region) => whole.with_region(region.clone()),
                        None => Ok(whole),
                    }
                });
                Ok((detector.as_ref().map_err(|m| format!("--mask: {m}"))?, "the first frame"))
            }
        }
    }
}

/// The input stream, as [`StreamReader::open`] gives it (a relative `frames_dir` resolved
/// beside the input file).
pub type Input = StreamReader<Box<dyn BufRead + Send>>;

/// Runs the whole stream from `input` to `writer`.
pub fn run(input: Input, writer: impl Write, output_name: &str, config: Config) -> CliResult {
    let camera_detector = match config.camera.as_ref() {
        Some(cam) => {
            let (w, h) = cam.image_size();
            let detector = RidgeDetector::new(w, h, cam.mirror_circle(), config.params);
            Some(match &config.region {
                Some(region) => {
                    detector.with_region(region.clone()).map_err(|m| CliError::new(format!("--mask: {m}")))?
                }
                None => detector,
            })
        }
        None => None,
    };
    let detectors = Arc::new(Detectors {
        params: config.params,
        camera: camera_detector,
        region: config.region,
        from_first_frame: OnceLock::new(),
        laser_off: stripe::LaserOffCache::new(config.colour),
        colour: config.colour,
        sites: config.colour.site_origin().map(|origin| (origin, OnceLock::new())),
        luma_hint: std::sync::atomic::AtomicBool::new(false),
        static_ambient: config.static_ambient.map(DecodedGray::from_gray),
        along: AlongStripeTally::default(),
    });
    let threads = config.threads.max(1);
    let window = 2 * threads + 2;
    let (token_tx, token_rx) = sync_channel::<()>(window);
    for _ in 0..window {
        token_tx.send(()).map_err(|e| e.to_string())?;
    }
    let (job_tx, job_rx) = sync_channel::<Job>(window);
    let (out_tx, out_rx) = sync_channel::<Outcome>(window);
    // The reader reports a fatal input error (bad JSON, empty stream) at the position it occurred.
    let read_error: Arc<Mutex<Option<(usize, String)>>> = Arc::default();
    spawn_reader(
        input,
        ReaderSettings { producer: config.producer.clone(), strict: config.strict },
        token_rx,
        job_tx,
        out_tx.clone(),
        read_error.clone(),
    );
    let job_rx = Arc::new(Mutex::new(job_rx));
    let overlay = config.overlay.clone().map(Arc::new);
    for _ in 0..threads {
        let (job_rx, out_tx, detectors, overlay) = (job_rx.clone(), out_tx.clone(), detectors.clone(), overlay.clone());
        std::thread::spawn(move || worker(&job_rx, &out_tx, &detectors, overlay.as_deref().map(|p| p.as_path())));
    }
    drop(out_tx);
    let out = StreamWriter::new(writer, output_name).binary(config.binary);
    write_in_order(out_rx, token_tx, out, config.keep_going, &read_error)?;
    detectors.along.verdict(config.params.along_stripe_px, config.params.along_stripe_window_px())
}

/// What the reader thread does with the stream besides reading it.
struct ReaderSettings {
    producer: String,
    strict: bool,
}

fn spawn_reader(
    mut stream: Input,
    settings: ReaderSettings,
    tokens: Receiver<()>,
    jobs: SyncSender<Job>,
    direct: SyncSender<Outcome>,
    read_error: Arc<Mutex<Option<(usize, String)>>>,
) {
    std::thread::spawn(move || {
        let ReaderSettings { producer, strict } = settings;
        let mut frames_dir: Option<String> = None;
        let (mut index, mut frames) = (0, 0u64);
        loop {
            // Wait until the writer has room for one more record in flight.
            if tokens.recv().is_err() {
                return;
            }
            let record = match stream.next_record() {
                Ok(Some(r)) => r,
                Ok(None) => {
                    if stream.cut_short() {
                        let message = stream.cut_short_message();
                        if strict {
                            *read_error.lock().unwrap_or_else(|e| e.into_inner()) =
                                Some((index, format!("{message}; refused with --strict")));
                            return;
                        }
                        omni_cli::warn("omni-ridge", &format!("{message}; passing on complete: false"));
                        let status = omni_formats::stream::Status::cut_short(frames, message);
                        let _ = direct.send((index, Ok(Record::Status(status))));
                    }
                    return;
                }
                Err(e) => {
                    *read_error.lock().unwrap_or_else(|e| e.into_inner()) = Some((index, e.to_string()));
                    return;
                }
            };
            let record = match record {
                Record::Header(mut h) => {
                    frames_dir = h.frames_dir.clone();
                    h.producers.push(producer.clone());
                    // Headers go straight to the writer: nothing to compute.
                    if direct.send((index, Ok(Record::Header(h)))).is_err() {
                        return;
                    }
                    index += 1;
                    continue;
                }
                other => other,
            };
            frames += u64::from(matches!(record, Record::Frame(_)));
            if jobs.send(Job { index, record, frames_dir: frames_dir.clone() }).is_err() {
                return;
            }
            index += 1;
        }
    });
}

fn worker(jobs: &Mutex<Receiver<Job>>, out: &SyncSender<Outcome>, detectors: &Detectors, overlay: Option<&Path>) {
    loop {
        let job = {
            let rx = jobs.lock().unwrap_or_else(|e| e.into_inner());
            match rx.recv() {
                Ok(j) => j,
                Err(_) => return,
            }
        };
        let result = match job.record {
            Record::Frame(mut frame) => {
                match process_frame(&mut frame, job.frames_dir.as_deref(), detectors, overlay) {
                    Ok(()) => Ok(Record::Frame(frame)),
                    Err(message) => Err(FrameError { seq: frame.seq, path: frame.path.clone(), message }),
                }
            }
            other => Ok(other),
        };
        if out.send((job.index, result)).is_err() {
            return;
        }
    }
}

/// Fills `frame.stripe`; laser-off frames (no laser on) get an empty stripe. Points triangulated
/// from an earlier stripe (a stream that went through omni-triangulate) no longer belong to it
/// and are dropped.
fn process_frame(
    frame: &mut omni_formats::stream::Frame,
    frames_dir: Option<&str>,
    detectors: &Detectors,
    overlay: Option<&Path>,
) -> Result<(), String> {
    frame.points = None;
    if frame.lasers.is_empty() {
        frame.stripe = Some(Vec::new());
        return Ok(());
    }
    let path = frame.resolve_path(frames_dir, &frame.path);
    if detectors.colour == ColourSpec::default() && !detectors.luma_hint.swap(true, Ordering::Relaxed) {
        warn_if_colour_read_as_luma(&path);
    }
    let (mut points, img) = detect_points(frame, frames_dir, &path, detectors, overlay.is_some())?;
    let along = detectors.params.along_stripe_px;
    if along > 0.0 {
        let short = stripe::refuse_short_stripes(points, detectors.params.along_stripe_window_px());
        let tally = &detectors.along;
        tally.kept.fetch_add(short.kept.len(), Ordering::Relaxed);
        tally.refused.fetch_add(short.refused, Ordering::Relaxed);
        tally.longest_bits.fetch_max(short.longest_px.to_bits(), Ordering::Relaxed);
        points = short.kept;
    }
    if let (Some(dir), Some(img)) = (overlay, img) {
        // A mosaic read at its sites is drawn at its own half size.
        let rgb = match &detectors.sites {
            Some((origin, _)) => stripe::draw_overlay(&img, &RidgeDetector::points_on_mosaic_sites(&points, *origin)),
            None => stripe::draw_overlay(&img, &points),
        };
        write_rgb_png(&dir.join(format!("{:06}.png", frame.seq)), img.width, img.height, &rgb)
            .map_err(|e| e.to_string())?;
    }
    frame.stripe = Some(points);
    Ok(())
}

/// The stripe points of a laser frame, less its laser-off frame or the static ambient, and its
/// image as read unless it was an 8-bit frame (grey, or colour read by a channel without a
/// mosaic) with no overlay to draw: those are measured on their own bytes.
fn detect_points(
    frame: &omni_formats::stream::Frame,
    frames_dir: Option<&str>,
    path: &Path,
    detectors: &Detectors,
    keep_image: bool,
) -> Result<(Vec<stripe::StripePoint>, Option<GrayImage>), String> {
    let mut decoded = stripe::load_frame_decoded_cached(frame, frames_dir, &detectors.laser_off)?;
    if let (Some(ambient), None) = (&detectors.static_ambient, &frame.ambient_path) {
        decoded.subtract_saturating(ambient).map_err(|m| format!("{}: static ambient's {m}", path.display()))?;
    }
    if let (DecodedGray::Eight { width, height, data }, false, None) = (&decoded, keep_image, &detectors.sites) {
        let (detector, what) = detectors.for_size(*width, *height)?;
        stripe::check_frame_size(*width, *height, detector, what).map_err(|m| format!("{}: {m}", path.display()))?;
        let pixels = stripe::Frame { width: *width, height: *height, data, max_value: 255.0 };
        return Ok((detector.detect_frame(&pixels, &mut stripe::Scratch::default()), None));
    }
    let img = decoded.into_gray();
    let Some((origin, at_sites)) = &detectors.sites else {
        let (detector, what) = detectors.for_size(img.width, img.height)?;
        let points = stripe::frame_points(&img, detector, what).map_err(|m| format!("{}: {m}", path.display()))?;
        return Ok((points, Some(img)));
    };
    // Read at the mosaic's sites: a frame of half the size, its points mapped back.
    let (detector, what) = detectors.for_size(2 * img.width, 2 * img.height)?;
    let half = at_sites.get_or_init(|| detector.for_mosaic_sites(*origin));
    let points = stripe::mosaic_site_points(&img, detector, half, *origin, what)
        .map_err(|m| format!("{}: {m}", path.display()))?;
    Ok((points, Some(img)))
}

/// Colour frames read as luma lose a coloured laser on lit surfaces: says so once, naming the
/// options that read its colour.
fn warn_if_colour_read_as_luma(path: &Path) {
    if omni_vision::image_io::is_colour_file(path) == Some(true) {
        omni_cli::warn(
            "omni-ridge",
            &format!(
                "{}: colour frames are read as luma, in which a red stripe on lit paper is darker than the paper; \
                 --laser red|green|blue reads the laser's colour",
                path.display()
            ),
        );
    }
}

/// Writes outcomes in input order, returning a token per record written.
fn write_in_order(
    outcomes: Receiver<Outcome>,
    tokens: SyncSender<()>,
    mut out: StreamWriter<impl Write>,
    keep_going: bool,
    read_error: &Mutex<Option<(usize, String)>>,
) -> CliResult {
    let mut pending: BTreeMap<usize, Result<Record, FrameError>> = BTreeMap::new();
    let mut next = 0;
    let mut failures: Vec<String> = Vec::new();
    // Laser frames in which no stripe was found: not errors, but worth a count.
    let mut without_stripe = 0u64;
    let progress = omni_cli::progress(None, "frames");
    for (index, result) in outcomes {
        pending.insert(index, result);
        while let Some(result) = pending.remove(&next) {
            let record = match result {
                Ok(Record::Status(mut status)) => {
                    status.frames_failed += failures.len() as u64;
                    status.errors.extend(failures.iter().cloned());
                    status.extra.insert(FRAMES_WITHOUT_STRIPE.into(), without_stripe.into());
                    Record::Status(status)
                }
                Ok(Record::Frame(f)) => {
                    without_stripe +=
                        u64::from(!f.lasers.is_empty() && f.stripe.as_ref().is_some_and(|s| s.is_empty()));
                    Record::Frame(f)
                }
                Ok(record) => record,
                Err(fe) => {
                    let message = format!("frame {}: {}", fe.seq, fe.message);
                    if !keep_going {
                        return Err(CliError::new(message));
                    }
                    omni_cli::warn("omni-ridge", &message);
                    failures.push(message.clone());
                    Record::Error(FrameError { message, ..fe })
                }
            };
            let is_frame = matches!(record, Record::Frame(_) | Record::Error(_));
            out.write(&record)?;
            if is_frame {
                progress.inc(1);
            }
            next += 1;
            // The reader may have stopped already; a missing receiver is not an error here.
            let _ = tokens.send(());
        }
    }
    progress.finish_and_clear();
    out.flush()?;
    if let Some((_, message)) = read_error.lock().unwrap_or_else(|e| e.into_inner()).take() {
        return Err(CliError::new(message));
    }
    if !failures.is_empty() {
        return Err(CliError::new(format!("{} {KEEP_GOING_SUMMARY} (see the error records)", failures.len())));
    }
    Ok(())
}

/// The static-ambient estimate of the stream in `input` (a file: it is read twice), from the
/// frames [`stripe::static_ambient_frames`] picks.
pub fn estimate_static_ambient(input: &Path, colour: &ColourSpec) -> CliResult<GrayImage> {
    let mut stream = StreamReader::open(input)?;
    let (mut frames, mut dirs) = (Vec::new(), Vec::new());
    let mut frames_dir: Option<String> = None;
    while let Some(record) = stream.next_record()? {
        match record {
            Record::Header(h) => frames_dir = h.frames_dir,
            Record::Frame(f) => {
                frames.push(*f);
                dirs.push(frames_dir.clone());
            }
            _ => {}
        }
    }
    let name = input.display();
    let picked = stripe::static_ambient_frames(&frames).map_err(|m| CliError::new(format!("{name}: {m}")))?;
    let mut images = Vec::with_capacity(picked.len());
    for i in picked {
        let path = frames[i].resolve_path(dirs[i].as_deref(), &frames[i].path);
        images
            .push(omni_vision::image_io::load_frame_channel(&path, colour).map_err(|e| CliError::new(e.to_string()))?);
    }
    stripe::static_ambient(&images).map_err(|m| CliError::new(format!("{name}: static ambient: {m}")))
}
