//! omni-ridge: sub-pixel laser-stripe centres for every frame of an omniscan stream.

mod pipeline;

use clap::Parser;
use omni_cli::{CliError, CliResult};
use omni_vision::colour::{Channel, ColourSpec};
use omni_vision::stripe::{Method, RidgeParams, Sampling, ScanLines, SearchRegion};
use std::path::PathBuf;
use std::process::ExitCode;

const AFTER_HELP: &str = "\
Each frame record's image (path resolved against the header's frames_dir) is loaded, its laser-off
frame (ambient_path, decoded once however many frames share it) subtracted if present, and searched
inside the mirror annulus (from --camera; without it: the whole frame, as for an ordinary lens;
--roi or --mask narrow either). Colour frames are read as luma unless told: --laser red reads
R - (G+B)/2, in which white and grey surfaces cancel and a red stripe on lit paper stands out (in
luma it is darker than the paper); above 3/4 of full scale the red level itself takes over, so a
close laser's white, saturated core reads full scale, not 0. --channel red|green|blue reads one
channel; --bayer ORDER demosaics raw sensor mosaics first. The stripe is measured across its own
normal, in every direction, about once per pixel of its length (--sampling rays: along rays from
the mirror centre instead, which misses stripes within 30 degrees of a ray). Stripes wider than
--max-width (a close laser's 20 px line, a saturated 60 px core) are found in the frame binned 2x2,
4x4 or 8x8, where they are a few px wide, and re-measured on the frame's own pixels. Each point [u, v, peak intensity, width px, quality flags] goes into the
record's `stripe` field; other records and fields pass through untouched. Points closer than 1.5 px
to a stripe's end, lopsided profiles (a stripe cut by a silhouette or a crease) and isolated specks
are dropped; the blur's pull on curved stripes is removed with the blur measured on the frame.
Without laser-off frames, textured or patterned light (window bars, posters, checks) gives false
stripes, and in a lit room a curved object's silhouette edge runs under the last px of its stripes,
whose profiles are then dropped as cut (a bench cylinder kept 75 % of its stripes' length instead of
86 %); --static-ambient estimates the laser-off frame from the scan itself (a sensor at rest).

Methods: centroid (the paper's threshold + intensity centroid, Eq. 16), windowed (centroid with the
threshold subtracted, the default), gauss (log-parabola fit), blais-rioux, hessian (Steger).
Saturated stripes are always located at the centre of the saturated plateau.

Exit codes: 0 ok (also when a reader such as `| head` closes the pipe), 1 bad input or a frame that
failed (with --keep-going: at the end), 2 usage error; a signal (Ctrl-C, kill) ends it once its temporary files are removed, and the shell sees 128 + the signal's number (130 for Ctrl-C).

Examples:
  omni-sim scan --scene room.json | omni-ridge --camera camera.json | omni-triangulate ...
  omni-ridge photos.jsonl --laser red -o ridges.jsonl       # colour photos of a red line laser
  omni-ridge raw.jsonl --bayer rggb --laser red --roi 0,100,1280,520
  omni-ridge photos.jsonl --laser red --one-stripe-per column   # reflections dropped
  omni-ridge scan.jsonl -o ridges.jsonl --camera camera.json --method gauss --threshold 40
  omni-ridge scan.jsonl -o ridges.jsonl --overlay check/ --keep-going
  omni-ridge scan.jsonl -o ridges.jsonl --camera camera.json --static-ambient";

/// Finds the laser stripe's sub-pixel centres in every frame of a stream.
#[derive(Parser, Debug)]
#[command(term_width = 0, version, about, after_help = AFTER_HELP)]
struct Args {
    /// Input stream (JSON Lines); `-` for stdin.
    #[arg(default_value = "-")]
    input: PathBuf,
    /// Output stream; `-` for stdout. Files are written atomically.
    #[arg(short, long, default_value = "-")]
    output: PathBuf,
    /// camera.json: gives the mirror centre, the valid annulus and the expected frame size.
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Stripe-centre estimator.
    #[arg(long, default_value = "windowed", value_parser = parse_method)]
    method: Method,
    /// Where profiles are sampled: normal (across each stripe, every direction) or rays (from
    /// the mirror centre, the earlier detector).
    #[arg(long, default_value = "normal", value_parser = parse_sampling)]
    sampling: Sampling,
    /// Intensity threshold in the frame's units (0–255 or 0–65535) [default: 4 % of full scale].
    #[arg(long, allow_negative_numbers = true)]
    threshold: Option<f64>,
    /// Narrowest accepted stripe (px, threshold crossing to crossing along the ray).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    min_width: f64,
    /// Widest stripe measured at the frame's own scale (px, threshold crossing to crossing);
    /// wider ones are searched at coarser scales (--max-scale).
    #[arg(long, default_value_t = 12.0, allow_negative_numbers = true)]
    max_width: f64,
    /// Scale (px) of the Gaussian derivatives of the hessian method.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    hessian_sigma: f64,
    /// Fit each point along the stripe through the stripe's points within up to this many px of
    /// arc on either side (0 = off). Across the normal: over 3 px a line through the stripe's
    /// kept points once a wider parabola's bend is taken out, and over longer arcs (growing from
    /// 3 px for as long as a longer arc agrees with the shorter ones within their noise, so
    /// tight curves, steps and stripe ends keep a short arc) a parabola through the arc (with
    /// --sampling rays: a line over the whole arc). Averages speckle
    /// and noise (the simulator's cylinder under speckle of contrast 0.25: 0.051 px RMS alone,
    /// 0.036 at 3, 0.031 at 10; without speckle 0.012 alone, 0.010 at 3) at the price of lateral
    /// resolution: a step along the stripe rises 10-90 % over about 5 px (2 px without the fit).
    /// Stripes shorter than the shortest arc's window (2 × PX end to end, at most 6 px; 2 × PX
    /// along rays) are refused: their points are dropped with a warning, and a run in which no
    /// stripe is that long fails.
    #[arg(long, default_value_t = 0.0, value_name = "PX", allow_negative_numbers = true)]
    along_stripe: f64,
    /// The lens's blur (Gaussian PSF σ, px; pixel area not included), whose pull on curved
    /// stripes (σ²κ/2 towards their centre of curvature) is removed, and whose shift of a
    /// lopsided laser's peak (a tail on one side) is undone [default: from the --camera file:
    /// its lens_blur_px (omni-calib-receiver measures it on the boards' edges), else what its
    /// optics imply (F-number, wavelength, pixel pitch, defocus); without either, the pull's
    /// blur is measured on each frame's stripes, which counts a wide laser sheet's own width as
    /// blur and over-corrects wide curved stripes, and only the pixel's and the sampling's blur
    /// is undone at a lopsided peak].
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    optics_blur: Option<f64>,
    /// The laser's cross-section, if known: a Gaussian core with a one-sided exponential tail
    /// holding SHARE (0-0.9) of the light, LENGTH (0.05-50) core σ long (0,1: a symmetric
    /// laser). Points are then led from their profiles' tops to the sheet's peak by what this
    /// cross-section, blurred by the lens (--optics-blur or the camera's; give it), the pixel and
    /// the sampling, predicts at the stripe's width, wherever the stripe's own top shape cannot
    /// tell: pieces too short or too speckled for it, and stripes whose width is mostly the
    /// blur's (FWHM under about 1.4 × the blur's with the sampling: 3.7 px behind a 0.7 px
    /// lens). There, with the windowed and hessian methods, the offset the cross-section
    /// predicts for the estimator's centre itself (at the stripe's width and the threshold)
    /// leads the points, and the profiles' leans from their tops only as far as they depart
    /// from it beyond their noise (speckle makes the tops noisy). Clipped points are led to the
    /// sheet's peak from their plateau's centre, which lies towards the tail the more the
    /// brighter the stripe: the cross-section, at the width of the stripe's
    /// unclipped profiles within 48 px (dimmer parts of the surface), tells how far down the
    /// plateau's edges were read. The tail's side comes from the stripe. The red line laser of
    /// the hand-held photographs in ../shared/data/real-laser-handheld measures 0.17,4. Not
    /// with --sampling rays.
    #[arg(long, value_name = "SHARE,LENGTH")]
    laser_tail: Option<omni_model::LaserProfile>,
    /// Coarsest scale at which stripes wider than --max-width are searched: 1 (off), 2, 4, 8 or
    /// 16, frames binned that many pixels square. A stripe is found at the scale where it is a
    /// few pixels wide and re-measured on the frame's own pixels (a 20 px stripe at 4, a
    /// saturated 60 px core at 8).
    #[arg(long, default_value_t = 8, value_name = "N")]
    max_scale: u32,
    /// Write each frame with its detected centres drawn as DIR/<seq>.png.
    #[arg(long, value_name = "DIR")]
    overlay: Option<PathBuf>,
    /// On a bad frame, write an error record and go on (exit code 1 at the end).
    #[arg(long)]
    keep_going: bool,
    /// Refuse an input stream without its final status record (cut short upstream); without
    /// it the tool warns and passes `complete: false` on.
    #[arg(long)]
    strict: bool,
    /// Write the stream's stripe and point arrays in binary after each frame's line (stream
    /// version 2): the same numbers bit for bit, far cheaper to write and read through a pipe.
    /// Every omniscan tool and the Python package read both; text tools (jq) read JSON only.
    #[arg(long)]
    binary: bool,
    /// Estimate the ambient light from the scan itself and subtract it from every frame without a
    /// laser-off frame: the per-pixel median of up to 31 frames at different mirror angles. For a
    /// sensor that stands still during the scan, under patterned or textured light; needs INPUT
    /// as a file (it is read twice).
    #[arg(long)]
    static_ambient: bool,
    /// Read one channel of colour frames instead of their luma (a grey frame is an error).
    #[arg(long, value_name = "CHANNEL", value_parser = ["luma", "red", "green", "blue"], conflicts_with = "laser")]
    channel: Option<String>,
    /// The laser's colour: read colour frames as that channel minus the mean of the other two,
    /// clamped at 0 (red: R - (G+B)/2), so that white and grey surfaces cancel; above 3/4 of
    /// full scale the channel's own level takes over (w = 4 (1 - R/full) on (G+B)/2), so that a
    /// saturated white core reads full scale.
    #[arg(long, value_name = "COLOUR", value_parser = ["red", "green", "blue"])]
    laser: Option<String>,
    /// Frames are raw Bayer mosaics (grey images, 8 or 16 bit) with this colour filter order,
    /// row 0 then row 1 (rggb: R G / G B): demosaiced (Malvar-He-Cutler), then read as
    /// --channel or --laser says (luma without either). Red and blue are sampled one pixel in
    /// four, so a stripe's centre moves by up to about 0.1 px with where it falls between
    /// their columns; a stripe along a row or column keeps that shift all along it.
    #[arg(long, value_name = "ORDER", value_parser = ["rggb", "bggr", "grbg", "gbrg"])]
    bayer: Option<String>,
    /// With --bayer and a red or blue --laser or --channel: read the mosaic at that colour's
    /// own sites instead of demosaicing it, a frame of half the size whose every sample was
    /// measured (green and the third colour averaged around each site for --laser); points are
    /// given in the frame's pixels. Stripes 5 px wide and more come out about twice as precise
    /// (5 px: 0.038 against 0.073 px RMS in the simulator), those crossing the mosaic's columns
    /// or rows several times more; narrower ones along a row or column, sampled every 2 px,
    /// move as much as demosaiced (up to about 0.1 px).
    #[arg(long, requires = "bayer")]
    bayer_sites: bool,
    /// Keep only points in this rectangle of pixels (x, y of its top-left pixel, width, height),
    /// within the camera's annulus or, without --camera, the whole frame.
    #[arg(long, value_name = "X,Y,W,H", value_parser = parse_roi, conflicts_with = "mask")]
    roi: Option<SearchRegion>,
    /// Keep only points on the non-zero pixels of this grey image (the frames' size): a
    /// valid-pixel mask, e.g. a lens's vignetted corners or the sensor's own body left out.
    #[arg(long, value_name = "PNG")]
    mask: Option<PathBuf>,
    /// For an ordinary laser-triangulation sensor (the camera beside the laser, the stripe
    /// moving along the image's columns with depth, or its rows): its laser lights one point of
    /// each column (row), so a stripe crossing the same column (or the one beside it) as one at
    /// least twice as bright is dropped as its reflection (glossy paper, a shiny edge). Stripes
    /// are compared by their connected pieces' median intensity, so pieces alike in brightness
    /// are both kept; a piece at least half of whose points are outshone goes whole, one less
    /// outshone keeps the rest. With --bayer-sites a line is one site (2 px). Not for the
    /// catadioptric sensor, where one image line can cross the stripe on two walls.
    #[arg(long, value_name = "LINE", value_parser = parse_scan_lines)]
    one_stripe_per: Option<ScanLines>,
    /// Worker threads (0: one per core; at most 1024).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = omni_cli::parse_threads)]
    threads: usize,
}

fn parse_method(s: &str) -> Result<Method, String> {
    s.parse()
}

fn parse_sampling(s: &str) -> Result<Sampling, String> {
    s.parse()
}

fn parse_scan_lines(s: &str) -> Result<ScanLines, String> {
    s.parse()
}

fn parse_roi(s: &str) -> Result<SearchRegion, String> {
    let v: Vec<u32> = s
        .split(',')
        .map(|x| x.trim().parse::<u32>().map_err(|_| format!("\"{x}\" is not a whole number of pixels")))
        .collect::<Result<_, _>>()?;
    let [x, y, w, h] = v[..] else {
        return Err(format!("expected X,Y,W,H (4 numbers), got {}", v.len()));
    };
    if w == 0 || h == 0 {
        return Err("the width and height must be at least 1 px".into());
    }
    Ok(SearchRegion::Rect { x0: x, y0: y, x1: x.saturating_add(w), y1: y.saturating_add(h) })
}

/// The colour reading the options ask for.
fn colour_spec(args: &Args) -> ColourSpec {
    let channel = match (&args.laser, args.channel.as_deref()) {
        (Some(c), _) => Channel::Laser(c.parse().expect("clap checked the colour")),
        (None, None | Some("luma")) => Channel::Luma,
        (None, Some(c)) => Channel::Single(c.parse().expect("clap checked the colour")),
    };
    ColourSpec {
        channel,
        bayer: args
            .bayer
            .as_deref()
            .map(|b| omni_vision::colour::BayerPattern::parse(b).expect("clap checked the order")),
        sites: args.bayer_sites,
    }
}

/// The mask image as one flag per pixel (non-zero: valid).
fn load_mask(path: &std::path::Path) -> CliResult<SearchRegion> {
    let img = omni_vision::image_io::load_gray(path)?;
    Ok(SearchRegion::Mask(std::sync::Arc::new(img.data.iter().map(|&v| v != 0).collect())))
}

fn main() -> ExitCode {
    omni_cli::main("omni-ridge", || {
        let args = omni_cli::parse_args::<Args>()?;
        let params = RidgeParams {
            method: args.method,
            sampling: args.sampling,
            threshold: args.threshold,
            min_width: args.min_width,
            max_width: args.max_width,
            hessian_sigma: args.hessian_sigma,
            along_stripe_px: args.along_stripe,
            optics_blur_px: args.optics_blur,
            max_scale: args.max_scale,
            mosaic: args.bayer.is_some(),
            laser_profile: args.laser_tail,
            one_stripe_per: args.one_stripe_per,
        };
        params.validate().map_err(CliError::usage)?;
        let (camera, params) = match &args.camera {
            Some(path) => {
                let (file, model) = omni_formats::CameraFile::load(path)?;
                let (w, h) = model.image_size();
                model.mirror_circle().check_in_frame(w, h).map_err(|e| format!("{}: {e}", path.display()))?;
                (Some(model), params.with_lens_blur_of(&file).map_err(|e| format!("{}: {e}", path.display()))?)
            }
            None => (None, params),
        };
        if params.laser_profile.is_some() && params.optics_blur_px.is_none() {
            omni_cli::warn(
                "omni-ridge",
                "--laser-tail without the lens's blur (--optics-blur, or a --camera file with lens_blur_px or optics): \
                 the cross-section's offsets are computed as if behind a perfect lens",
            );
        }
        if let Some(dir) = &args.overlay {
            omni_cli::create_output_dir("--overlay", dir)?;
        }
        let threads = if args.threads == 0 {
            std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
        } else {
            args.threads
        };
        let colour = colour_spec(&args);
        colour.validate().map_err(CliError::usage)?;
        let static_ambient = if args.static_ambient {
            if args.input == std::path::Path::new("-") {
                return Err(CliError::usage("--static-ambient reads the stream twice: give it as a file, not stdin"));
            }
            Some(pipeline::estimate_static_ambient(&args.input, &colour)?)
        } else {
            None
        };
        let config = pipeline::Config {
            params,
            camera,
            overlay: args.overlay,
            keep_going: args.keep_going,
            binary: args.binary,
            threads,
            producer: format!("omni-ridge {}", env!("CARGO_PKG_VERSION")),
            strict: args.strict,
            static_ambient,
            colour,
            region: match &args.mask {
                Some(path) => Some(load_mask(path)?),
                None => args.roi.clone(),
            },
        };
        run(&args.input, &args.output, config)
    })
}

fn run(input: &std::path::Path, output: &std::path::Path, config: pipeline::Config) -> CliResult {
    let stream = omni_formats::stream::StreamReader::open(input)?;
    if output == std::path::Path::new("-") {
        // Stdout's own buffer is a line's: a frame's record would reach the pipe in 1 KiB writes.
        let stdout = std::io::BufWriter::with_capacity(1 << 16, std::io::stdout().lock());
        return pipeline::run(stream, stdout, "stdout", config);
    }
    let out_name = output.display().to_string();
    let mut outcome: CliResult = Ok(());
    let written = omni_formats::io::write_atomic(output, |w| {
        outcome = pipeline::run(stream, w, &out_name, config);
        match &outcome {
            // Per-frame failures with --keep-going still leave a complete output stream.
            Err(e) if !pipeline::is_keep_going_summary(e) => Err(std::io::Error::other(e.message().to_string())),
            _ => Ok(()),
        }
    });
    outcome?;
    written?;
    Ok(())
}
