//! omni-calib-receiver: calibrate the catadioptric camera from checkerboard images.

//!
//! Argument parsing only: each command is one call into [`omni_calib::receiver::session`], whose
//! messages this prints on stderr and whose errors it maps to exit codes.

use clap::{Parser, Subcommand};
use omni_calib::receiver::session::{self, Error, Reporter};
use omni_calib::receiver::{ModelKind, export};
use omni_cli::CliError;
use std::io::Write as _;
use std::path::PathBuf;
use std::sync::OnceLock;

#[derive(Parser, Debug)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    version,
    about = "Calibrate the receiver camera (catadioptric, or an ordinary pinhole or fisheye camera) from \
checkerboard images: detect the corners, fit a camera model, write camera.json with the fitted model and a report.",
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    after_help = "Examples:\n  \
omni-calib-receiver --board board.json -o camera.json boards/*.png\n  \
omni-calib-receiver --board board.json --model ocam --export-ocam calib_results.txt boards/\n  \
omni-calib-receiver --board board.json --save-corners corners.json --overlay check/ boards/\n  \
omni-calib-receiver --board board.json --corners corners.json --model mei --export-kalibr camchain.yaml\n  \
omni-calib-receiver --board board.json --model pinhole --export-opencv calib.yaml boards/     (OpenCV calibrateCamera's model)\n  \
omni-calib-receiver --board board.json --model fisheye --export-kalibr camchain.yaml boards/\n  \
omni-calib-receiver --board board.json --annulus 511.5,511.5,102.5,493 boards/\n  \
omni-calib-receiver --board board.json --annulus auto boards/\n  \
omni-calib-receiver --board board.json --rim-image lit_room.png boards/\n  \
omni-calib-receiver find-annulus lit_room.png    (prints CX,CY,R_IN,R_OUT for --annulus)\n  \
omni-calib-receiver import-ocam calib_results.txt -o camera.json\n  \
omni-calib-receiver export camera.json --to opencv -o omnidir.yaml\n  \
omni-calib-receiver convert camera.json --to ocam -o ocam.json     (fits OCamCalib's model to the rays)\n  \
omni-calib-receiver import-kalibr camchain.yaml -o camera.json\n  \
omni-calib-receiver import-opencv omnidir.yaml -o camera.json\n  \
omni-calib-receiver import-opencv --model fisheye fisheye.yaml -o camera.json\n  \
omni-calib-receiver query --camera camera.json < questions.txt     (lines \"u v\" → rays, \"x y z\" → pixels)\n\n\
Models: mei (unified sphere model + radial-tangential distortion, as Kalibr omni-radtan and OpenCV \
omnidir), ocam (Scaramuzza polynomial, as OCamCalib), hyperbolic (the exact mirror of --mirror with \
focal length and principal point fitted); for ordinary cameras: pinhole (radial-tangential k1 k2 p1 p2 k3, \
as OpenCV calibrateCamera; alias opencv-pinhole), pinhole-radtan (k1 k2 p1 p2, k3 = 0, as Kalibr pinhole-radtan), \
fisheye (Kannala-Brandt k1..k4, as OpenCV cv::fisheye and Kalibr pinhole-equi; aliases kannala-brandt, \
pinhole-equi). ocam, hyperbolic, pinhole and fisheye fits are checked against a Mei fit of the same images. \
Images may be files or directories (png, jpg, tif). \
Images whose board is not found, has too few corners, or fits much worse than the others are \
reported and left out. camera.json is written only if the calibration succeeded. \
It also carries the lens's blur measured on the boards' edges (lens_blur_px: the PSF's σ in px, \
the median over the images), which omni-ridge --camera removes from curved stripes.\n\
Exported Kalibr and OpenCV files describe the unit sphere (x, y, −z) of the omniscan world about \
the viewpoint, the pinhole and fisheye ones a camera frame (x, y, −z) (written into the files as a comment; see \
docs/FORMATS.md).\n\
Exit codes: 0 ok, 1 bad input or failed calibration, 2 usage error."
)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    calib: CalibArgs,
}

#[derive(clap::Args, Debug)]
struct CalibArgs {
    /// The checkerboard (board.json: inner corners and square size).
    #[arg(long, required = true)]
    board: Option<PathBuf>,
    /// Camera model to fit: mei, ocam, hyperbolic, pinhole, pinhole-radtan or fisheye (see below).
    #[arg(long, default_value = "mei")]
    model: ModelKind,
    /// Read corners from this file (see --save-corners) instead of detecting them.
    #[arg(long, conflicts_with = "images")]
    corners: Option<PathBuf>,
    /// Write the detected corners to this file (JSON, `omniscan.corners`).
    #[arg(long)]
    save_corners: Option<PathBuf>,
    /// Write one PNG per image with detected (green) and reprojected (red) corners here.
    #[arg(long, value_name = "DIR")]
    overlay: Option<PathBuf>,
    /// Output camera.json (`-` = stdout).
    #[arg(short, long, default_value = "camera.json")]
    output: PathBuf,
    /// For --model hyperbolic: camera.json of kind hyperbolic giving the mirror (a, b, rim);
    /// default: the paper's mirror.
    #[arg(long)]
    mirror: Option<PathBuf>,
    /// For --model hyperbolic: also fit the camera's offset from the mirror's focus and its tilt
    /// (a non-central model; for a camera off the focus, which the model check warns about).
    #[arg(long)]
    non_central: bool,
    /// Also export OCamCalib calib_results.txt (needs --model ocam).
    #[arg(long, value_name = "FILE")]
    export_ocam: Option<PathBuf>,
    /// Also export Kalibr camchain.yaml: omni + radtan (--model mei), pinhole + radtan (--model
    /// pinhole-radtan) or pinhole + equidistant (--model fisheye).
    #[arg(long, value_name = "FILE")]
    export_kalibr: Option<PathBuf>,
    /// Also export an OpenCV FileStorage YAML: omnidir K, D, xi (--model mei), calibrateCamera's
    /// camera_matrix, distortion_coefficients (--model pinhole, pinhole-radtan) or fisheye K, D
    /// (--model fisheye).
    #[arg(long, value_name = "FILE")]
    export_opencv: Option<PathBuf>,
    /// The image topic written into --export-kalibr's camchain.yaml (`rostopic`).
    #[arg(long, value_name = "TOPIC", default_value = export::DEFAULT_ROSTOPIC)]
    rostopic: String,
    /// Also report a held-out test RMS: K-fold validation (each K-th image posed under the model
    /// fitted to the others; K more fits). 0 = none.
    #[arg(long, value_name = "K", default_value_t = 0)]
    folds: usize,
    /// Also report each parameter's σ from a leave-one-image-out jackknife (one more fit per
    /// used image): the fit's own σ takes the corners' errors as independent, which corners
    /// biased alike within an image (print, board flatness, blur) are not.
    #[arg(long)]
    jackknife: bool,
    /// Huber threshold of the robust loss (px).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    huber_px: f64,
    /// Fit by plain least squares: no Huber loss, no per-image weights, no image rejected as an
    /// outlier. The cost OpenCV and Kalibr minimise, to compare RMS values with theirs.
    #[arg(long, conflicts_with = "huber_px")]
    least_squares: bool,
    /// Where the fitted model's single viewpoint sits in the world frame (mm). Board images fix
    /// the rays' directions, not the origin: 0,0,0 makes the viewpoint the origin; the mirror's
    /// focus 0,0,2c (0,0,80 for the paper's mirror) keeps SENSOR.md's frame, origin at the camera.
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0,0", allow_hyphen_values = true)]
    viewpoint_mm: String,
    /// The mirror annulus in the image (px): centre x, centre y, inner and outer rim radius, as
    /// read off an image of a lit scene; or `auto`: found in the board images themselves (the
    /// rim circle of their per-pixel range: the mirror is where the content changed). Corners are
    /// searched inside it and dropped where their refinement window reaches a rim (the rim edge
    /// biases them); the principal point starts at its centre; the fitted mei/ocam model is
    /// valid inside it. The annulus used is printed and written into the report. Default: the
    /// whole image.
    #[arg(long, value_name = "CX,CY,R_IN,R_OUT|auto", conflicts_with = "rim_image", allow_hyphen_values = true)]
    annulus: Option<String>,
    /// Find the annulus (outer mirror rim and, if visible, the blind centre) in this image of a
    /// lit scene (same camera and size as the board images) instead of giving --annulus.
    #[arg(long, value_name = "FILE")]
    rim_image: Option<PathBuf>,
    /// Board images (files or directories).
    #[arg(required_unless_present = "corners")]
    images: Vec<PathBuf>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Find the mirror annulus (outer rim and, if visible, blind centre) in an image of a lit
    /// scene, or in the per-pixel range of several images (e.g. the board images), and print it
    /// as CX,CY,R_IN,R_OUT (px) for --annulus. Exit 1 with the reason if no rim circle is found.
    #[command(after_help = "Example:\n  omni-calib-receiver find-annulus lit_room.png")]
    FindAnnulus {
        /// One lit image, or several images / directories of one camera.
        #[arg(required = true)]
        images: Vec<PathBuf>,
    },
    /// Convert an OCamCalib calib_results.txt into camera.json (kind ocam). The centre's pixel
    /// origin is read from its header: OCamCalib v3 ("starting from 0 (C convention)") as
    /// written, older files (Matlab, 1-based) minus one.
    #[command(after_help = "Example:\n  omni-calib-receiver import-ocam calib_results.txt -o camera.json")]
    ImportOcam {
        /// OCamCalib's calib_results.txt (`-` = stdin).
        input: PathBuf,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Ask a calibration: pixels give world rays, 3-D points give pixels. One question per line:
    /// `u v` (pixel) or `x y z` (point, mm, world frame), or JSON `[u, v]`, `[x, y, z]`,
    /// `{"px": [u, v]}`, `{"point_mm": [x, y, z]}`. A text answer repeats the question, then
    /// `ox oy oz dx dy dz` (ray origin in mm, unit direction) or `u v`, or `none` where the
    /// mirror does not see it; --json answers with one object per line.
    /// Example: echo "600 240" | omni-calib-receiver query --camera camera.json
    Query {
        /// The calibration (camera.json).
        #[arg(long)]
        camera: PathBuf,
        /// Questions (`-` = stdin).
        #[arg(short, long, default_value = "-")]
        input: PathBuf,
        /// Answers (`-` = stdout).
        #[arg(short, long, default_value = "-")]
        output: PathBuf,
        /// Answer in JSON (one object per line) instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write an existing camera.json in another tool's format without re-fitting: ocam
    /// (OCamCalib calib_results.txt, from kind ocam), kalibr (camchain.yaml) or opencv
    /// (FileStorage YAML: omnidir, calibrateCamera or fisheye), both from kind mei, pinhole or
    /// fisheye (Kalibr: a pinhole with k3 = 0).
    #[command(after_help = "Example:\n  omni-calib-receiver export camera.json --to opencv -o omnidir.yaml")]
    Export {
        /// The calibration (camera.json).
        camera: PathBuf,
        /// Target format: ocam, kalibr or opencv.
        #[arg(long, value_parser = ["ocam", "kalibr", "opencv"])]
        to: String,
        /// For kalibr: the image topic (`rostopic`).
        #[arg(long, value_name = "TOPIC", default_value = export::DEFAULT_ROSTOPIC)]
        rostopic: String,
        /// Output file (`-` = stdout).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Convert a calibration into another model without a re-fit to boards: the target model is
    /// fitted to the source's rays over its mirror annulus. Prints the largest ray (deg) and
    /// pixel (px) difference and refuses (exit 1, no output) beyond the tolerances.
    #[command(after_help = "Example:\n  omni-calib-receiver convert camera.json --to ocam -o ocam.json")]
    Convert {
        /// The calibration (camera.json).
        camera: PathBuf,
        /// Target model: mei, ocam, hyperbolic, pinhole, pinhole-radtan or fisheye.
        #[arg(long)]
        to: ModelKind,
        /// For --to hyperbolic: camera.json of kind hyperbolic giving the mirror (a, b, rim);
        /// default: the source's mirror if it is hyperbolic, else the paper's.
        #[arg(long)]
        mirror: Option<PathBuf>,
        /// Largest ray difference accepted (deg).
        #[arg(long, default_value_t = 0.05)]
        max_ray_deg: f64,
        /// Largest pixel difference accepted (px).
        #[arg(long, default_value_t = 0.2)]
        max_pixel_px: f64,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Convert one camera of a Kalibr camchain.yaml into camera.json: omni + radtan (kind mei),
    /// pinhole + radtan (kind pinhole), pinhole + equidistant (kind fisheye). Kalibr's sphere or
    /// camera frame (x, y, z) is (x, y, −z) of the omniscan world; the numbers are the same.
    #[command(after_help = "Example:\n  omni-calib-receiver import-kalibr camchain.yaml -o camera.json")]
    ImportKalibr {
        /// Kalibr's camchain.yaml (`-` = stdin).
        input: PathBuf,
        /// Which camera of the chain.
        #[arg(long, default_value = "cam0")]
        cam: String,
        /// Where the camera's viewpoint sits in the world frame (mm); default: the one an
        /// omniscan export keeps in the file (omniscan_viewpoint_mm), else 0,0,0.
        #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
        viewpoint_mm: Option<String>,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
    /// Convert an OpenCV FileStorage YAML file into camera.json: cv::omnidir (K, D, xi; kind
    /// mei), calibrateCamera (camera_matrix or K, distortion_coefficients or D = k1 k2 p1 p2 [k3];
    /// kind pinhole) or cv::fisheye (K, D = k1..k4; kind fisheye), with image_width and
    /// image_height. OpenCV's sphere or camera frame (x, y, z) is (x, y, −z) of the omniscan world.
    #[command(after_help = "Example:\n  omni-calib-receiver import-opencv calib.yaml -o camera.json")]
    ImportOpencv {
        /// The OpenCV FileStorage YAML file (`-` = stdin).
        input: PathBuf,
        /// Which OpenCV model: auto (xi: omnidir; camera_matrix: pinhole; K and D alone are
        /// ambiguous and refused), omnidir, pinhole or fisheye.
        #[arg(long, default_value = "auto")]
        model: export::OpencvModel,
        /// Where the camera's viewpoint sits in the world frame (mm); default: the one an
        /// omniscan export keeps in the file (omniscan_viewpoint_mm), else 0,0,0.
        #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
        viewpoint_mm: Option<String>,
        /// Output camera.json (`-` = stdout).
        #[arg(short, long, default_value = "camera.json")]
        output: PathBuf,
    },
}

const TOOL: &str = "omni-calib-receiver";

fn main() -> std::process::ExitCode {
    omni_cli::main(TOOL, || {
        let args = omni_cli::parse_args::<Args>()?;
        let out = Stderr::default();
        match args.command {
            Some(Command::ImportOcam { input, output }) => session::import_ocam(&input, &output),
            Some(Command::Query { camera, input, output, json }) => {
                session::query(&session::QueryOptions { camera, input, output, json })
            }
            Some(Command::Export { camera, to, rostopic, output }) => {
                session::export_camera(&session::ExportOptions { camera, to, rostopic, output }, &out)
            }
            Some(Command::Convert { camera, to, mirror, max_ray_deg, max_pixel_px, output }) => {
                let opts = session::ConvertOptions { camera, to, mirror, max_ray_deg, max_pixel_px, output };
                session::convert(&opts, &out)
            }
            Some(Command::ImportKalibr { input, cam, viewpoint_mm, output }) => {
                session::import_kalibr(&input, &cam, viewpoint_mm.as_deref(), &output)
            }
            Some(Command::ImportOpencv { input, model, viewpoint_mm, output }) => {
                session::import_opencv(&input, model, viewpoint_mm.as_deref(), &output)
            }
            Some(Command::FindAnnulus { images }) => session::find_annulus(&images, &out).and_then(|a| {
                // Through an io error, not println!: a closed stdout is a clean exit, not a panic.
                writeln!(std::io::stdout(), "{:.3},{:.3},{:.3},{:.3}", a[0], a[1], a[2], a[3])
                    .map_err(|e| Error::Failed(e.to_string()))
            }),
            None => calibrate(args.calib, &out),
        }
        .map_err(cli_error)
    })
}

fn calibrate(a: CalibArgs, out: &Stderr) -> Result<(), Error> {
    let board = a.board.ok_or_else(|| Error::Usage("--board is required".into()))?;
    let opts = session::CalibrateOptions {
        board,
        model: a.model,
        corners: a.corners,
        save_corners: a.save_corners,
        overlay: a.overlay,
        output: a.output,
        mirror: a.mirror,
        non_central: a.non_central,
        export_ocam: a.export_ocam,
        export_kalibr: a.export_kalibr,
        export_opencv: a.export_opencv,
        rostopic: a.rostopic,
        folds: a.folds,
        jackknife: a.jackknife,
        huber_px: a.huber_px,
        least_squares: a.least_squares,
        viewpoint_mm: a.viewpoint_mm,
        annulus: a.annulus,
        rim_image: a.rim_image,
        images: a.images,
    };
    session::calibrate(&opts, out)
}

fn cli_error(e: Error) -> CliError {
    match e {
        Error::Usage(m) => CliError::usage(m),
        Error::Failed(m) => CliError::new(m),
    }
}

/// Messages on stderr; the detection progress as a bar (drawn only on a terminal).
#[derive(Default)]
struct Stderr {
    bar: OnceLock<omni_cli::ProgressBar>,
}

impl Reporter for Stderr {
    fn say(&self, line: &str) {
        eprintln!("{line}");
    }
    fn warn(&self, message: &str) {
        omni_cli::warn(TOOL, message);
    }
    fn detection_started(&self, images: usize) {
        let _ = self.bar.set(omni_cli::progress(Some(images as u64), "detecting corners"));
    }
    fn image_detected(&self) {
        if let Some(bar) = self.bar.get() {
            bar.inc(1);
        }
    }
    fn detection_finished(&self) {
        if let Some(bar) = self.bar.get() {
            bar.finish_and_clear();
        }
    }
}
