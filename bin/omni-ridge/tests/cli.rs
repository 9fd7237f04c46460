//! The real omni-ridge binary on small synthetic streams: rings of known radius drawn around
//! the image centre, written as PNG frames next to a JSON Lines stream.

use omni_formats::stream::{Frame, Header, Record, Status, StreamReader, StreamWriter};
use omni_vision::image_io::{GrayImage, write_gray_png};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_omni-ridge");
const SIZE: u32 = 128;
const CENTRE: f64 = 63.5;

/// A ring of radius `radius` px (Gaussian profile σ = 1.5 px, peak `peak`) plus `extra(x, y)`.
fn ring(radius: f64, peak: f64, extra: impl Fn(f64, f64) -> f64) -> GrayImage {
    let mut img = GrayImage::new(SIZE, SIZE, 8);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (fx, fy) = (x as f64, y as f64);
            let d = (fx - CENTRE).hypot(fy - CENTRE) - radius;
            let v = peak * (-d * d / 4.5).exp() + extra(fx, fy);
            img.data[(y * SIZE + x) as usize] = v.round().clamp(0.0, 255.0) as u16;
        }
    }
    img
}

fn header(frames_dir: &Path) -> Record {
    let mut h = Header::new("test 1.0");
    h.frames_dir = Some(frames_dir.display().to_string());
    Record::Header(h)
}

fn frame(seq: u64, path: &str) -> Record {
    let mut f = Frame::new(seq, path, 0.5 * seq as f64, 0);
    f.extra.insert("exposure_us".into(), 800.into());
    Record::Frame(Box::new(f))
}

fn status(frames: u64) -> Record {
    Record::Status(Status::complete(frames))
}

fn stream_text(records: &[Record]) -> String {
    let mut w = StreamWriter::new(Vec::new(), "mem");
    for r in records {
        w.write(r).unwrap();
    }
    String::from_utf8(w.into_inner()).unwrap()
}

/// Three frames with rings of radius 30, 40, 50 px, and the stream describing them.
fn scene(dir: &Path) -> String {
    for (i, r) in [30.0, 40.0, 50.0].iter().enumerate() {
        write_gray_png(&dir.join(format!("f{i}.png")), &ring(*r, 180.0, |_, _| 0.0)).unwrap();
    }
    let mut recs = vec![header(dir)];
    recs.extend((0..3).map(|i| frame(i, &format!("f{i}.png"))));
    recs.push(status(3));
    stream_text(&recs)
}

fn run(args: &[&str], stdin: &str) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A tool that refuses its arguments exits without reading stdin: the pipe may be closed.
    if let Err(e) = child.stdin.take().unwrap().write_all(stdin.as_bytes()) {
        assert_eq!(e.kind(), std::io::ErrorKind::BrokenPipe, "writing the tool's stdin: {e}");
    }
    child.wait_with_output().unwrap()
}

fn records(text: &[u8]) -> Vec<Record> {
    StreamReader::new(text, "out").map(|r| r.unwrap()).collect()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn stdin_to_stdout_finds_the_rings_and_passes_everything_else_through() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--method", "gauss"], &scene(dir.path()));
    assert!(out.status.success(), "{}", stderr(&out));
    let recs = records(&out.stdout);
    assert_eq!(recs.len(), 5);
    let Record::Header(h) = &recs[0] else { panic!("no header first") };
    assert_eq!(h.producers[0], "test 1.0");
    assert!(h.producers[1].starts_with("omni-ridge "), "{:?}", h.producers);
    for (i, radius) in [30.0, 40.0, 50.0].iter().enumerate() {
        let Record::Frame(f) = &recs[i + 1] else { panic!("record {} is not a frame", i + 1) };
        assert_eq!(f.seq, i as u64);
        assert_eq!(f.extra["exposure_us"], 800);
        let pts = f.stripe.as_ref().unwrap();
        // About one point per pixel row or column the ring crosses: 2√2 per px of radius per
        // octant, ≈ 0.9 per px of its length.
        let expected = 0.85 * std::f64::consts::TAU * radius;
        assert!(pts.len() as f64 >= expected, "frame {i}: {} points", pts.len());
        let worst = pts.iter().map(|p| ((p.u - CENTRE).hypot(p.v - CENTRE) - radius).abs()).fold(0.0, f64::max);
        assert!(worst < 0.05, "frame {i}: worst radial error {worst} px");
        // Intensity: the contrast of the Gaussian-sampled profile (σ = 0.8 px smooths the
        // σ = 1.5 px ring's peak of 180 to 180·1.5/1.7 ≈ 159); width: at the 4 % threshold.
        let odd = pts.iter().find(|p| (p.intensity - 159.0).abs() > 5.0 || p.width < 6.0 || p.width > 10.0);
        assert!(odd.is_none(), "{odd:?}");
    }
    assert_eq!(recs[4], status_without_stripe(3, 0));
}

/// The status omni-ridge writes: `frames_without_stripe` added.
fn status_without_stripe(frames: u64, without: u64) -> Record {
    let mut s = Status::complete(frames);
    s.extra.insert("frames_without_stripe".into(), without.into());
    Record::Status(s)
}

#[test]
fn output_is_the_same_for_any_thread_count_and_file_output_is_identical() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    let one = run(&["--threads", "1"], &text);
    let four = run(&["--threads", "4"], &text);
    assert!(one.status.success() && four.status.success());
    assert_eq!(one.stdout, four.stdout);
    let path = dir.path().join("out.jsonl");
    let file = run(&["-", "-o", path.to_str().unwrap(), "--overlay", dir.path().join("ov").to_str().unwrap()], &text);
    assert!(file.status.success(), "{}", stderr(&file));
    assert_eq!(std::fs::read(&path).unwrap(), one.stdout);
    for i in 0..3 {
        let ov = omni_vision::image_io::load_gray(&dir.path().join(format!("ov/{i:06}.png"))).unwrap();
        assert_eq!((ov.width, ov.height), (SIZE, SIZE));
    }
}

#[test]
fn binary_output_reads_back_to_the_same_records_and_says_version_2() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    let json = run(&[], &text);
    let binary = run(&["--binary"], &text);
    assert!(json.status.success() && binary.status.success(), "{}", stderr(&binary));
    let (mut a, b) = (records(&json.stdout), records(&binary.stdout));
    let Record::Header(h) = &mut a[0] else { panic!() };
    assert_eq!(h.version, 1);
    h.version = omni_formats::stream::STREAM_BINARY_VERSION;
    assert_eq!(a, b, "the same numbers, bit for bit");
    assert!(binary.stdout.len() < json.stdout.len() * 2 / 3, "{} vs {} bytes", binary.stdout.len(), json.stdout.len());
}

#[test]
fn laser_off_frame_removes_ambient_light() {
    let dir = tempfile::tempdir().unwrap();
    // A lamp: a bright, gently sloped patch that crosses the threshold around the ring.
    let lamp = |x: f64, y: f64| 70.0 * (-((x - 90.0).powi(2) + (y - 70.0).powi(2)) / 800.0).exp();
    write_gray_png(&dir.path().join("on.png"), &ring(40.0, 150.0, lamp)).unwrap();
    write_gray_png(&dir.path().join("off.png"), &ring(40.0, 0.0, lamp)).unwrap();
    let Record::Frame(mut f) = frame(0, "on.png") else { unreachable!() };
    f.ambient_path = Some("off.png".into());
    let text = stream_text(&[header(dir.path()), Record::Frame(f.clone())]);
    let out = run(&[], &text);
    assert!(out.status.success(), "{}", stderr(&out));
    let Record::Frame(g) = &records(&out.stdout)[1] else { panic!() };
    let pts = g.stripe.as_ref().unwrap();
    assert!(pts.len() as f64 >= 0.85 * std::f64::consts::TAU * 40.0, "{} points", pts.len());
    let worst = pts.iter().map(|p| ((p.u - CENTRE).hypot(p.v - CENTRE) - 40.0).abs()).fold(0.0, f64::max);
    assert!(worst < 0.05, "worst {worst}");
    // Without the laser-off frame the lamp's slope under the ring tilts the profiles the same
    // way along the ring: the centres are those of the profiles' tops, which the slope barely
    // moves (worst 0.034 px measured; 0.092 px when the windowed centroid's lean was kept).
    f.ambient_path = None;
    let out = run(&[], &stream_text(&[header(dir.path()), Record::Frame(f)]));
    let Record::Frame(g) = &records(&out.stdout)[1] else { panic!() };
    let lit = g.stripe.as_ref().unwrap();
    let worst_lit = lit.iter().map(|p| ((p.u - CENTRE).hypot(p.v - CENTRE) - 40.0).abs()).fold(0.0, f64::max);
    eprintln!("without the laser-off frame: {} points, worst {worst_lit:.3} px", lit.len());
    assert!(worst_lit < 0.05 && lit.len() <= pts.len(), "{} points, worst {worst_lit}", lit.len());
}

#[test]
fn bad_frames_are_named_and_stop_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let good = scene(dir.path());
    std::fs::write(dir.path().join("text.png"), "not an image").unwrap();
    let bytes = std::fs::read(dir.path().join("f0.png")).unwrap();
    std::fs::write(dir.path().join("cut.png"), &bytes[..bytes.len() / 3]).unwrap();
    for (file, expect) in [("missing.png", "missing.png"), ("text.png", "not a PNG"), ("cut.png", "truncated")] {
        let text = good.replace("f1.png", file);
        let out_path = dir.path().join("out.jsonl");
        let out = run(&["-o", out_path.to_str().unwrap()], &text);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{file}: {err}");
        assert!(err.contains("frame 1") && err.contains(expect) && err.lines().count() == 1, "{file}: {err}");
        assert!(!out_path.exists(), "{file}: half-written output left behind");
    }
}

#[test]
fn keep_going_writes_error_records_and_fails_at_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path()).replace("f1.png", "missing.png");
    let out = run(&["--keep-going"], &text);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let recs = records(&out.stdout);
    assert_eq!(recs.len(), 5);
    let Record::Error(e) = &recs[2] else { panic!("{:?}", recs[2]) };
    assert!(e.seq == 1 && e.message.contains("missing.png"), "{e:?}");
    assert!(matches!(&recs[3], Record::Frame(f) if f.stripe.as_ref().is_some_and(|s| s.len() > 200)));
    let Record::Status(s) = &recs[4] else { panic!() };
    assert_eq!(s.frames_failed, 1);
    assert!(stderr(&out).contains("1 frames failed"));
}

#[test]
fn frames_of_another_size_than_the_camera_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    let cam = dir.path().join("camera.json");
    omni_formats::write_doc(&cam, &small_camera(160)).unwrap();
    let out = run(&["--camera", cam.to_str().unwrap()], &text);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("frame 0") && err.contains("128x128") && err.contains("160x128"), "{err}");
}

/// A camera file whose focal length puts the mirror's annulus far beyond the frame (a typo, a
/// unit mix-up) is refused before any frame is read, naming the file; it once sized the
/// search for that imaginary image and ran out of memory.
#[test]
fn a_camera_whose_mirror_misses_the_frame_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    for fx in [1e6, 1e12, 1e20] {
        let mut file = small_camera(128);
        let omni_formats::CameraSpec::Hyperbolic(p) = &mut file.model else { unreachable!() };
        (p.fx_px, p.fy_px) = (fx, fx);
        let cam = dir.path().join("far.json");
        omni_formats::write_doc(&cam, &file).unwrap();
        let out_path = dir.path().join("out.jsonl");
        let out = run(&["--camera", cam.to_str().unwrap(), "-o", out_path.to_str().unwrap()], &text);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "fx {fx}: {err}");
        assert!(err.contains("far.json") && err.contains("does not reach the 128 × 128 frame"), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(!out_path.exists());
    }
}

#[test]
fn empty_and_malformed_streams_are_errors() {
    let out = run(&[], "");
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("empty stream"), "{}", stderr(&out));
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    let broken: String = text.lines().take(2).map(|l| format!("{l}\n")).collect::<String>() + "{\"type\": \"frame\",\n";
    let out = run(&[], &broken);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("stdin: line 3"), "{}", stderr(&out));
    // The records before the bad line were written.
    assert_eq!(records(&out.stdout).len(), 2);
}

#[test]
fn closed_downstream_pipe_is_a_clean_exit() {
    let dir = tempfile::tempdir().unwrap();
    write_gray_png(&dir.path().join("f.png"), &ring(40.0, 180.0, |_, _| 0.0)).unwrap();
    let mut recs = vec![header(dir.path())];
    recs.extend((0..300).map(|i| frame(i, "f.png")));
    let input = dir.path().join("in.jsonl");
    std::fs::write(&input, stream_text(&recs)).unwrap();
    let mut child = Command::new(BIN).arg(&input).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut first).unwrap();
    // The reader (and with it the pipe) is dropped here, like `| head -1`.
    assert!(first.contains("header"));
    let status = child.wait().unwrap();
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert_eq!(status.code(), Some(0), "{err}");
}

#[test]
fn help_teaches_and_bad_usage_exits_2() {
    let out = Command::new(BIN).arg("--help").output().unwrap();
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("Examples") && help.contains("blais-rioux"));
    let out = Command::new(BIN).args(["--method", "median"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = run(&["--min-width", "5", "--max-width", "3"], "");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    for (tail, says) in [("0.17", "SHARE,LENGTH"), ("0.95,4", "tail_weight"), ("0.2,x", "tail length \"x\"")] {
        let out = run(&["--laser-tail", tail], "");
        assert_eq!(out.status.code(), Some(2), "{tail}: {}", stderr(&out));
        assert!(stderr(&out).contains("--laser-tail") && stderr(&out).contains(says), "{tail}: {}", stderr(&out));
    }
}

#[test]
fn a_laser_tail_without_the_lens_blur_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--laser-tail", "0.17,4"], &scene(dir.path()));
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("warning: --laser-tail without the lens's blur"), "{}", stderr(&out));
    let out = run(&["--laser-tail", "0.17,4", "--optics-blur", "0.7"], &scene(dir.path()));
    assert!(out.status.success() && stderr(&out).is_empty(), "{}", stderr(&out));
}

#[test]
fn a_stream_cut_short_is_warned_about_and_passed_on_incomplete_or_refused_with_strict() {
    let dir = tempfile::tempdir().unwrap();
    let text = scene(dir.path());
    // Drop the final status record.
    let cut: String = text.lines().filter(|l| !l.contains("\"status\"")).map(|l| format!("{l}\n")).collect();
    assert_ne!(cut, text, "the scene has a status record");
    let out = run(&[], &cut);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("without its status record"), "{}", stderr(&out));
    let recs = records(&out.stdout);
    let Some(Record::Status(s)) = recs.last() else { panic!("no status passed on: {:?}", recs.last()) };
    assert!(!s.complete && s.frames == 3, "{s:?}");
    let strict = run(&["--strict"], &cut);
    assert_eq!(strict.status.code(), Some(1), "{}", stderr(&strict));
    assert!(stderr(&strict).contains("--strict") && stderr(&strict).lines().count() == 1, "{}", stderr(&strict));
}

#[test]
fn negative_numbers_reach_the_option_check() {
    for (flag, name) in [("--min-width", "min-width"), ("--along-stripe", "along-stripe"), ("--threshold", "threshold")]
    {
        let out = run(&[flag, "-1"], "");
        assert_eq!(out.status.code(), Some(2), "{flag}: {}", stderr(&out));
        assert!(
            stderr(&out).contains(name) && !stderr(&out).contains("unexpected argument"),
            "{flag}: {}",
            stderr(&out)
        );
    }
}

#[test]
fn a_relative_frames_dir_is_found_beside_the_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    scene(&frames);
    // A manifest beside the frames directory naming it relatively, read from another directory.
    let text = scene(&frames).replace(&frames.display().to_string(), "frames");
    let manifest = dir.path().join("scan.jsonl");
    std::fs::write(&manifest, text).unwrap();
    let elsewhere = tempfile::tempdir().unwrap();
    let out = Command::new(BIN).arg(&manifest).current_dir(elsewhere.path()).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(records(&out.stdout).len(), 5);
}

/// A static pattern (two bright bars that look like stripes) under a ring that moves from
/// frame to frame: `--static-ambient` takes the scan's per-pixel median as its laser-off frame.
#[test]
fn static_ambient_removes_a_pattern_that_stays_put() {
    let dir = tempfile::tempdir().unwrap();
    let bars = |x: f64, _y: f64| if (18.0..21.0).contains(&x) || (104.0..107.0).contains(&x) { 90.0 } else { 0.0 };
    let radii: Vec<f64> = (0..7).map(|k| 26.0 + 4.0 * k as f64).collect();
    let mut recs = vec![header(dir.path())];
    for (k, r) in radii.iter().enumerate() {
        write_gray_png(&dir.path().join(format!("p{k}.png")), &ring(*r, 150.0, bars)).unwrap();
        recs.push(frame(k as u64, &format!("p{k}.png")));
    }
    recs.push(status(radii.len() as u64));
    let input = dir.path().join("scan.jsonl");
    std::fs::write(&input, stream_text(&recs)).unwrap();
    let off_ring = |out: &Output| -> (usize, f64) {
        assert!(out.status.success(), "{}", stderr(out));
        let frames = records(&out.stdout).into_iter().filter_map(|r| match r {
            Record::Frame(f) => Some(f),
            _ => None,
        });
        let (mut off, mut worst) = (0, 0.0f64);
        for (f, r) in frames.zip(&radii) {
            for p in f.stripe.as_ref().unwrap() {
                let e = ((p.u - CENTRE).hypot(p.v - CENTRE) - r).abs();
                if e > 2.0 { off += 1 } else { worst = worst.max(e) }
            }
        }
        (off, worst)
    };
    let (off, _) = off_ring(&run(&[input.to_str().unwrap()], ""));
    assert!(off > 50, "the bars should be taken for stripes without the estimate: {off} points off the rings");
    let (off, worst) = off_ring(&run(&["--static-ambient", input.to_str().unwrap()], ""));
    assert!(off == 0 && worst < 0.06, "{off} points off the rings, worst {worst:.3} px on them");
    // Read twice, so not from stdin; and one mirror angle is not a sweep.
    let out = run(&["--static-ambient", "-"], &stream_text(&recs));
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("not stdin"), "{}", stderr(&out));
    let few = dir.path().join("few.jsonl");
    std::fs::write(&few, stream_text(&recs[..3])).unwrap();
    let out = run(&["--static-ambient", few.to_str().unwrap()], "");
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("few.jsonl") && stderr(&out).contains("mirror angles, the stream has 2"),
        "{}",
        stderr(&out)
    );
}

/// A straight stripe `length` px long (σ 1.5 px across, ends tapering over 2 px) at y = 100.
fn short_stripe(length: f64) -> GrayImage {
    let mut img = GrayImage::new(SIZE, SIZE, 8);
    let (x0, x1) = (CENTRE - 0.5 * length, CENTRE + 0.5 * length);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (fx, fy) = (x as f64, y as f64);
            let along = ((fx - x0).min(x1 - fx) / 2.0).clamp(0.0, 1.0);
            let v = 180.0 * along * (-(fy - 100.0).powi(2) / 4.5).exp();
            img.data[(y * SIZE + x) as usize] = v.round() as u16;
        }
    }
    img
}

#[test]
fn an_along_stripe_fit_longer_than_the_stripe_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_gray_png(&dir.path().join("ring.png"), &ring(40.0, 180.0, |_, _| 0.0)).unwrap();
    write_gray_png(&dir.path().join("short.png"), &short_stripe(14.0)).unwrap();
    let only_short = stream_text(&[header(dir.path()), frame(0, "short.png"), status(1)]);
    // ±3 px fits on the 14 px stripe.
    let out = run(&["--along-stripe", "3"], &only_short);
    assert!(out.status.success(), "{}", stderr(&out));
    let Record::Frame(f) = &records(&out.stdout)[1] else { panic!("no frame") };
    assert!(f.stripe.as_ref().unwrap().len() >= 5, "{:?}", f.stripe);
    // Up to ±10 px across the normal too: its longer arcs stop where the stripe ends.
    let out = run(&["--along-stripe", "10"], &only_short);
    assert!(out.status.success(), "{}", stderr(&out));
    let Record::Frame(f) = &records(&out.stdout)[1] else { panic!("no frame") };
    assert!(f.stripe.as_ref().unwrap().len() >= 5, "{:?}", f.stripe);
    // Along rays ±10 px is one arc, which the stripe is too short for: the run fails, names
    // the option and says what would fit; the output file is not written.
    let path = dir.path().join("out.jsonl");
    let mut child = Command::new(BIN)
        .args(["--sampling", "rays", "--along-stripe", "10", "-o", path.to_str().unwrap()])
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(only_short.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(e.contains("--along-stripe 10 px") && e.contains("longer than every stripe found"), "{e}");
    assert!(e.contains("use --along-stripe ") && e.contains(" or less"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(!path.exists());
    // With a long stripe in the stream the short one's points are dropped, with a warning.
    let mixed = stream_text(&[header(dir.path()), frame(0, "ring.png"), frame(1, "short.png"), status(2)]);
    let out = run(&["--sampling", "rays", "--along-stripe", "10"], &mixed);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("points refused, on stripes shorter than its 20 px window"), "{}", stderr(&out));
    let recs = records(&out.stdout);
    let (Record::Frame(ring), Record::Frame(short)) = (&recs[1], &recs[2]) else { panic!("frames") };
    assert!(ring.stripe.as_ref().unwrap().len() > 200);
    assert!(short.stripe.as_ref().unwrap().is_empty());
}

/// The ring of radius 40 px drawn in red on lit grey paper with dark checks (RGB, 8-bit): dimmer
/// than the paper in luma where it crosses it, bright in R − (G+B)/2.
fn red_ring_on_checks() -> Vec<u8> {
    let laser = ring(40.0, 90.0, |_, _| 0.0);
    let mut rgb = Vec::with_capacity(3 * (SIZE * SIZE) as usize);
    for y in 0..SIZE {
        for x in 0..SIZE {
            // The checks as a lens images them: averaged over 2 × 2 px (a camera with a colour
            // mosaic has an optical low-pass; sharper edges alias into false colour).
            let offsets = [-0.75, -0.25, 0.25, 0.75];
            let paper = offsets
                .iter()
                .flat_map(|&dy| offsets.iter().map(move |&dx| (x as f64 + dx, y as f64 + dy)))
                .map(|(sx, sy)| if ((sx / 16.0).floor() + (sy / 16.0).floor()) as i64 % 2 == 0 { 110.0 } else { 25.0 })
                .sum::<f64>()
                / 16.0;
            let l = laser.data[(y * SIZE + x) as usize] as f64;
            for c in [paper + l, paper + 0.1 * l, paper + 0.1 * l] {
                rgb.push(c.round().clamp(0.0, 255.0) as u8);
            }
        }
    }
    rgb
}

fn one_frame_stream(dir: &Path, file: &str) -> String {
    stream_text(&[header(dir), frame(0, file), status(1)])
}

#[test]
fn colour_frames_are_read_as_the_lasers_colour_and_raw_mosaics_demosaiced() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = red_ring_on_checks();
    omni_vision::image_io::write_rgb_png(&dir.path().join("c.png"), SIZE, SIZE, &rgb).unwrap();
    // The same frame as a raw RGGB mosaic (grey PNG).
    let mut mosaic = GrayImage::new(SIZE, SIZE, 8);
    for y in 0..SIZE as usize {
        for x in 0..SIZE as usize {
            let colour = [[0, 1], [1, 2]][y % 2][x % 2];
            mosaic.data[y * SIZE as usize + x] = rgb[3 * (y * SIZE as usize + x) + colour] as u16;
        }
    }
    write_gray_png(&dir.path().join("m.png"), &mosaic).unwrap();
    // Read as luma, a colour frame gets a hint naming the options (once), and stays a success.
    let out = run(&[], &one_frame_stream(dir.path(), "c.png"));
    let err = stderr(&out);
    assert!(out.status.success() && err.contains("read as luma") && err.lines().count() == 1, "{err}");
    // Worst radial error (px) and RMS: the mosaic samples red at one pixel in four, so a ring
    // of σ 1.5 px loses precision there.
    // Read at its red sites, the mosaic gives one point per 2 px of ring, in the frame's pixels,
    // five times as precise (measured: worst 0.067 px, RMS 0.028 px against 0.425 and 0.136),
    // and its overlay is drawn at half size.
    let overlay = dir.path().join("overlay");
    let sites = vec!["--bayer", "rggb", "--bayer-sites", "--laser", "red", "--overlay", overlay.to_str().unwrap()];
    for (file, args, points_per_px, worst_max, rms_max) in [
        ("c.png", vec!["--laser", "red"], 1.0, 0.08, 0.04),
        ("m.png", vec!["--bayer", "rggb", "--laser", "red"], 1.0, 0.6, 0.2),
        ("m.png", sites, 0.5, 0.15, 0.05),
    ] {
        let out = run(&args, &one_frame_stream(dir.path(), file));
        assert!(out.status.success(), "{file} {args:?}: {}", stderr(&out));
        let recs = records(&out.stdout);
        let Record::Frame(f) = &recs[1] else { panic!("no frame") };
        let pts = f.stripe.as_ref().unwrap();
        let least = 0.85 * points_per_px * std::f64::consts::TAU * 40.0;
        assert!(pts.len() as f64 >= least, "{file} {args:?}: {} points", pts.len());
        let errors: Vec<f64> = pts.iter().map(|p| (p.u - CENTRE).hypot(p.v - CENTRE) - 40.0).collect();
        let worst = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        eprintln!("{file} {args:?}: worst {worst:.3} px, rms {rms:.3} px");
        assert!(worst < worst_max && rms < rms_max, "{file} {args:?}: worst radial error {worst} px, rms {rms} px");
    }
    let drawn = omni_vision::image_io::load_gray(&overlay.join("000000.png")).unwrap();
    assert_eq!((drawn.width, drawn.height), (SIZE / 2, SIZE / 2));
}

#[test]
fn colour_options_that_do_not_fit_the_frame_are_named() {
    let dir = tempfile::tempdir().unwrap();
    write_gray_png(&dir.path().join("g.png"), &ring(40.0, 180.0, |_, _| 0.0)).unwrap();
    write_gray_png(&dir.path().join("odd.png"), &GrayImage::new(SIZE - 1, SIZE, 8)).unwrap();
    let rgb = red_ring_on_checks();
    omni_vision::image_io::write_rgb_png(&dir.path().join("c.png"), SIZE, SIZE, &rgb).unwrap();
    for (file, args, expect) in [
        ("g.png", vec!["--laser", "red"], "--laser red: the frame is grey"),
        ("g.png", vec!["--channel", "green"], "--channel green: the frame is grey"),
        ("c.png", vec!["--bayer", "rggb"], "--bayer rggb: the frame is a colour image"),
        ("odd.png", vec!["--bayer", "gbrg"], "--bayer gbrg: a 127x128 px frame is not a Bayer mosaic"),
    ] {
        let out = run(&args, &one_frame_stream(dir.path(), file));
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{file} {args:?}: {err}");
        assert!(err.contains(file) && err.contains(expect) && err.lines().count() == 1, "{file} {args:?}: {err}");
    }
    for args in [
        vec!["--channel", "violet"],
        vec!["--laser", "red", "--channel", "red"],
        vec!["--bayer", "rgbg"],
        vec!["--roi", "1,2,3"],
        vec!["--bayer-sites", "--laser", "red"],
    ] {
        let out = run(&args, "");
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
    }
    // The sites of one colour with one site per cell: red or blue.
    for (args, expect) in [
        (vec!["--bayer", "rggb", "--bayer-sites", "--laser", "green"], "not --laser green"),
        (vec!["--bayer", "rggb", "--bayer-sites"], "not luma"),
    ] {
        let out = run(&args, &one_frame_stream(dir.path(), "g.png"));
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("--bayer-sites") && err.contains(expect) && err.lines().count() == 1, "{args:?}: {err}");
    }
}

#[test]
fn the_whole_frame_is_searched_without_a_camera_and_a_roi_narrows_it() {
    // A straight vertical stripe near the left edge, outside the inscribed circle at its ends.
    let dir = tempfile::tempdir().unwrap();
    let mut img = GrayImage::new(SIZE, SIZE, 8);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let d = x as f64 - 12.3;
            img.data[(y * SIZE + x) as usize] = (150.0 * (-d * d / 4.5).exp()).round() as u16;
        }
    }
    write_gray_png(&dir.path().join("edge.png"), &img).unwrap();
    let blank = GrayImage::new(SIZE, SIZE, 8);
    write_gray_png(&dir.path().join("blank.png"), &blank).unwrap();
    let text = stream_text(&[header(dir.path()), frame(0, "edge.png"), frame(1, "blank.png"), status(2)]);
    let points = |args: &[&str]| {
        let out = run(args, &text);
        assert!(out.status.success(), "{}", stderr(&out));
        let recs = records(&out.stdout);
        let Record::Frame(f) = &recs[1] else { panic!("no frame") };
        // The blank frame is a frame without a stripe, not an error: counted in the status.
        assert_eq!(recs[3], status_without_stripe(2, 1));
        f.stripe.clone().unwrap()
    };
    let all = points(&[]);
    assert!(all.len() > 100 && all.iter().all(|p| (p.u - 12.3).abs() < 0.05), "{} points", all.len());
    // The corners of the frame beyond the inscribed circle (radius 63.5 px) are searched too.
    assert!(all.iter().any(|p| p.v < 10.0) && all.iter().any(|p| p.v > 117.0));
    let top = points(&["--roi", "0,0,128,40"]);
    assert!(!top.is_empty() && top.iter().all(|p| p.v < 39.5) && top.len() < all.len() / 2, "{} points", top.len());
}

/// The paper sensor's camera scaled to `width` × 128 px, centred on the frame.
fn small_camera(width: u32) -> omni_formats::CameraFile {
    let mut params = omni_model::HyperbolicParams::paper();
    (params.width, params.height) = (width, SIZE);
    (params.cx_px, params.cy_px) = ((width as f64 - 1.0) / 2.0, CENTRE);
    (params.fx_px, params.fy_px) = (243.75, 243.75);
    omni_formats::CameraFile::new(omni_formats::CameraSpec::Hyperbolic(params))
}

/// Mean signed radial error (px) of the points of the first frame `args` finds in `text`.
fn mean_radial_error(args: &[&str], text: &str, radius: f64) -> f64 {
    let out = run(args, text);
    assert!(out.status.success(), "{}", stderr(&out));
    let recs = records(&out.stdout);
    let Record::Frame(f) = &recs[1] else { panic!("no frame") };
    let pts = f.stripe.as_ref().unwrap();
    assert!(pts.len() > 150, "{} points", pts.len());
    pts.iter().map(|p| (p.u - CENTRE).hypot(p.v - CENTRE) - radius).sum::<f64>() / pts.len() as f64
}

/// A ring 5 px wide (σ 2.2 px) drawn sharp, so its width is all the sheet's and no lens pulls
/// it: measured on the frame, the blur's pull is taken as the profile's whole σ² (5.5 px² with
/// the sampling kernel) and the ring comes out 0.075 px too large; with the lens's blur known
/// (given, or from the camera file: its measured `lens_blur_px`, else its optics) only the
/// kernel's and the pixel's σ² are removed, and the ring keeps its radius (−0.0001 px).
#[test]
fn a_known_lens_blur_keeps_wide_curved_stripes_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let radius = 32.0;
    let mut img = GrayImage::new(SIZE, SIZE, 8);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let d = (x as f64 - CENTRE).hypot(y as f64 - CENTRE) - radius;
            img.data[(y * SIZE + x) as usize] = (160.0 * (-d * d / 9.68).exp()).round() as u16;
        }
    }
    write_gray_png(&dir.path().join("wide.png"), &img).unwrap();
    let text = stream_text(&[header(dir.path()), frame(0, "wide.png"), status(1)]);
    let measured = mean_radial_error(&[], &text, radius);
    let given = mean_radial_error(&["--optics-blur", "0"], &text, radius);
    assert!(measured > 0.05, "measured blur: {measured:+.4} px");
    assert!(given.abs() < 0.02, "--optics-blur 0: {given:+.4} px");
    // An in-focus F/2 lens on 10 µm pixels: σ 0.05 px of diffraction, next to nothing.
    let mut camera = small_camera(SIZE);
    camera.optics = Some(omni_model::Optics {
        wavelength_nm: 650.0,
        f_number: 2.0,
        pixel_pitch_um: 10.0,
        defocus_px: 0.0,
        focus_mm: None,
        speckle_patterns: 2,
    });
    let cam = dir.path().join("camera.json");
    omni_formats::write_doc(&cam, &camera).unwrap();
    let from_optics = mean_radial_error(&["--camera", cam.to_str().unwrap()], &text, radius);
    assert!((from_optics - given).abs() < 0.005, "camera optics {from_optics:+.4}, given 0: {given:+.4} px");
    // The blur a calibration measured (lens_blur_px) comes before the optics'.
    camera.lens_blur_px = Some(1.5);
    omni_formats::write_doc(&cam, &camera).unwrap();
    let measured_lens = mean_radial_error(&["--camera", cam.to_str().unwrap()], &text, radius);
    let given_lens = mean_radial_error(&["--optics-blur", "1.5"], &text, radius);
    assert!((measured_lens - given_lens).abs() < 1e-9 && (measured_lens - given).abs() > 0.02, "{measured_lens:+.4}");
}

/// A stream that went through omni-triangulate carries points made from its old stripes: they
/// are dropped with the stripes they came from, never passed on beside the new ones.
#[test]
fn points_of_an_earlier_stripe_are_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let triangulated: String = scene(dir.path())
        .lines()
        .map(|l| match l.contains("\"type\":\"frame\"") {
            true => l.replacen('{', "{\"points\":[[1.0,2.0,3.0,0,0,0]],", 1) + "\n",
            false => format!("{l}\n"),
        })
        .collect();
    assert!(records(triangulated.as_bytes()).iter().any(|r| matches!(r, Record::Frame(f) if f.points.is_some())));
    let out = run(&[], &triangulated);
    assert!(out.status.success(), "{}", stderr(&out));
    for r in records(&out.stdout) {
        if let Record::Frame(f) = r {
            assert!(f.points.is_none() && !f.stripe.unwrap().is_empty(), "frame {}", f.seq);
        }
    }
}
