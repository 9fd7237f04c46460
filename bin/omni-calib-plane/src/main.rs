//! omni-calib-plane: calibrate the swept light planes (the transmitter) from laser stripes on
//! posed checkerboards, and print the light-plane table of a calibrated scanner; `fixed` fits the
//! fixed light plane of a sensor without a scanning mirror.

use clap::{ArgGroup, Args, Parser, Subcommand};
use omni_calib::plane::{self, PlaneCalibOptions, inputs};
use omni_cli::{CliError, CliResult};
use omni_formats::rig::{BoardCornersFile, BoardPosesFile, RigFile};
use omni_formats::stream::StreamReader;
use omni_formats::{CameraFile, ScannerFile, io, read_doc, write_doc};
use omni_model::TransmitterParams;
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    name = "omni-calib-plane",
    version,
    about = "Calibrate the swept light planes (transmitter) of an omnidirectional line-laser scanner",
    long_about = "Calibrate the swept light planes (transmitter) of an omnidirectional line-laser scanner.\n\n\
        `fit` back-projects each laser frame's stripe onto the rig boards (posed with the calibrated \
        camera), fits one plane per frame as a check, then fits the physical transmitter (polygon \
        axis, encoder zero, per-facet tilt/pitch/radius errors, each laser's fan plane) to all frames \
        at once and writes scanner.json. `table` prints the light plane of any mirror angle. \
        `fixed` fits one fixed light plane (a line laser rigid with the camera, or the polygon \
        stopped) from stripe frames with a checkerboard in view and writes scanner.json of kind \
        fixed_planes. `tail` measures the laser's cross-section for omni-ridge's --laser-tail.",
    after_help = "Examples:\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --pose-image rig/pose.png --stripes stripes.jsonl -o scanner.json\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --pose-image rig/pose*.png --stripes stripes.jsonl -o scanner.json   # several pose images, averaged\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --board-corners corners.json --stripes stripes.jsonl -o scanner.json\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --board-poses poses.json --stripes - --initial nominal.json -o scanner.json\n  \
        omni-calib-plane table --scanner scanner.json --alpha 0:30:1\n  \
        omni-calib-plane table --scanner scanner.json --alpha 0:30:0.5 --laser 0 --facet 3 --json\n  \
        omni-calib-plane fixed --camera camera.json --board board.json --report plane.json -o scanner.json stripes/*.png\n  \
        omni-calib-plane tail --laser red wall/*.png"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit the transmitter model to stripe frames of a board rig; writes scanner.json.
    Fit(FitArgs),
    /// Print the light-plane table (normal, offset, slope, intercept per angle and laser).
    Table(TableArgs),
    /// Fit one fixed light plane to stripe frames with a checkerboard in view; writes
    /// scanner.json of kind fixed_planes.
    Fixed(FixedArgs),
    /// Measure the laser's cross-section (the share of its light in a one-sided tail and the
    /// tail's length) from stripe frames, for omni-ridge's --laser-tail.
    Tail(TailArgs),
}

#[derive(Args)]
#[command(after_help = "Why: a real line laser's cross-section is not a Gaussian: part of its light lies in a faint \
tail on one side of the sheet, which moves a narrow stripe's centre towards it (a few hundredths of a px at 2 px \
wide). Given the tail (--laser-tail SHARE,LENGTH), omni-ridge and omni-calib-plane fixed lead such stripes back to \
the sheet's peak.

How: in each frame the stripe detector finds the stripe over the whole frame; each unsaturated point's profile is \
sampled along the stripe's normal over six times the stripe's FWHM either side, its background (the line through \
the window's ends) taken out, aligned on its own peak and scaled to it. Windows whose ends differ or whose flanks \
step (a board's squares, an edge, another light) are left out. A frame's normals are turned to one side of \
the stripe: a straight or gently curved stripe's to the side of their mean direction, a ring's (a catadioptric \
camera's stripe about its mirror's axis) away from the mirror's centre (--camera; else the image's centre). \
The median of a frame's profiles is fitted by a Gaussian core with a one-sided exponential tail, widened by the lens's blur, the tail on either side; a frame \
counts where that fits clearly better than a Gaussian and tells the share from the length. The laser's figures \
are the medians over the frames that count, printed with their range and as the --laser-tail argument.

Frames: the stripe on a plain, matte, evenly lit target (a white wall, paper) that reaches six times the \
stripe's width to either side of it, not saturated, at least a few px wide (FWHM 5-20 px: the tail must be wider \
than the blur). Board frames work where the stripe crosses large white squares; most of their windows hold squares and are left out.

Prints one line per frame (profiles used, core σ and FWHM in px, share and length with their σ from the fit, the \
image direction the tail lies towards (x right, y down; a ring's outwards or inwards), the fit's residual against a \
Gaussian's), the frames left out and why, then the result with the frames' range (the honest spread: the fit's σ \
take the profiles' median as exact). Exit 1 when no frame counts.

Pixel values are taken as proportional to light: frames from a camera that gamma-encodes (sRGB, most colour \
cameras' PNG and JPEG) read the tail heavier (a (0.17, 4) tail encoded with gamma 2.2 over a background of 8 % \
of full scale reads (0.28, 4.7)); use linear (raw) frames. Points whose laser colour lies above 3/4 of full scale, \
where --laser's contrast weighs the other channels less and flattens the top, are left out like saturated ones: \
keep the stripe below that.

Examples:
  omni-calib-plane tail --laser red wall/*.png
  omni-calib-plane tail --laser red --optics-blur 0.8 --report tail.json stripes/
  omni-ridge --laser red --laser-tail $(omni-calib-plane tail --laser red --quiet wall/*.png) frames.jsonl")]
struct TailArgs {
    /// Stripe frames (files or directories of png/jpg/pgm).
    #[arg(required = true)]
    frames: Vec<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
    /// Stripe detector: widest stripe (px) at full resolution.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    max_width: f64,
    /// The lens's blur (Gaussian PSF σ, px): it widens the core, not the tail [default: from
    /// --camera, else 0].
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    optics_blur: Option<f64>,
    /// A camera file: its lens_blur_px (or optics) gives the lens's blur; a catadioptric
    /// camera's mirror gives the annulus searched and the centre its ring stripes curve about.
    #[arg(long)]
    camera: Option<PathBuf>,
    /// Fewest profiles with a clean background for a frame to count.
    #[arg(long, default_value_t = 30)]
    min_profiles: usize,
    /// Write the report (JSON, format omniscan.laser_tail_report) here as well.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Print only the result as SHARE,LENGTH (for --laser-tail); the frames' lines go to stderr.
    #[arg(long, short)]
    quiet: bool,
}

/// How a stripe frame is read and its stripe found (`fixed` and `tail`).
#[derive(Args)]
struct ReadArgs {
    /// The laser's colour: frames are read as that channel minus the mean of the other two
    /// (red: R - (G+B)/2) [default: red].
    #[arg(long, value_name = "COLOUR", value_parser = ["red", "green", "blue"], conflicts_with = "channel")]
    laser: Option<String>,
    /// Read one channel (or luma) instead of the laser's colour contrast.
    #[arg(long, value_name = "CHANNEL", value_parser = ["luma", "red", "green", "blue"])]
    channel: Option<String>,
    /// Stripe detector: intensity threshold in the read channel's units [default: 4 % of full scale].
    #[arg(long, allow_negative_numbers = true)]
    threshold: Option<f64>,
}

impl ReadArgs {
    /// What the frames are read as: the laser's colour contrast (red by default) or a channel.
    fn channel(&self) -> CliResult<omni_vision::colour::Channel> {
        use omni_vision::colour::{Channel, Colour};
        Ok(match (self.laser.as_deref(), self.channel.as_deref()) {
            (Some(c), _) => Channel::Laser(c.parse().map_err(CliError::usage)?),
            (None, None) => Channel::Laser(Colour::Red),
            (None, Some("luma")) => Channel::Luma,
            (None, Some(c)) => Channel::Single(c.parse().map_err(CliError::usage)?),
        })
    }
}

#[derive(Args)]
#[command(after_help = "How: in each frame the board's corners give its pose through the camera model (camera.json, \
any kind, e.g. from omni-calib-receiver --model mei), the stripe detector finds the laser's centres over the whole \
frame, and each centre's ray meets the board plane. Points inside the board's printed pattern (one square beyond \
the outer inner corners, widened by the board's white border: margin_mm in board.json, or --margin-mm) are points of the light plane. One plane is fitted to the points \
of all frames robustly (least median of squares, Tukey reweighting), then to the inliers by least squares in \
which each frame's points share its board's pose error (from the corners) and weigh by their own scatter about \
the frame's line, so that a board posed less surely, or a stripe read less surely, pulls the plane less however \
many points it carries.

It prints, per frame: corners and their RMS under the pose (px), stripe points on the board, inliers, the residual \
RMS and mean about the plane (mm), the straightness of the frame's stripe (RMS distance from its own best line in \
3-D, in mm and as imaged in px), and the leave-one-out RMS (the frame's points against the plane fitted without \
that frame, mm); then the plane (unit normal, distance from the camera in mm) with its σ from the fit (the points' \
scatter and the boards' pose errors) and from a jackknife over the frames (the honest one when frames differ by more than \
their boards' poses explain). --report writes all of it as JSON, with each frame's saturated stripe points on the board; \
scanner.json's report holds it too. Frames where more than a quarter of them are saturated are named in one \
warning: a clipped stripe is read at its plateau's middle, towards a lopsided laser's tail, so lower the exposure \
or the laser's power for calibration.

Frames whose board is not found, or whose board does not carry the stripe (fewer than --min-points points on it), \
are named and skipped, the latter with how many stripe points lie on the board's plane just beyond the pattern \
(a stripe along the white border); fewer than two usable frames is an error (exit 1). A board file whose size most frames \
contradict is an error naming the likely size.

Examples:
  omni-calib-plane fixed --camera camera.json --board board.json -o scanner.json stripes/im*.png
  omni-calib-plane fixed --camera camera.json --board board.json --laser green --margin-mm 2 --report plane.json --points points.jsonl -o scanner.json frames/
  omni-calib-plane fixed --camera camera.json --board board.json --stripes ridges.jsonl -o scanner.json   (centres from another detector's stream)
  omni-triangulate --camera camera.json --scanner scanner.json < stripes.jsonl   (the fixed plane, whatever the frames' alpha_deg)")]
struct FixedArgs {
    /// Calibrated receiver (camera.json, any model kind).
    #[arg(long)]
    camera: PathBuf,
    /// The checkerboard (board.json: inner corners and square size in mm).
    #[arg(long)]
    board: PathBuf,
    /// Stripe frames (colour images with the board in view; files or directories of png/jpg).
    #[arg(required_unless_present = "stripes", conflicts_with = "stripes")]
    frames: Vec<PathBuf>,
    /// Take the stripe centres from this stream (omniscan.stream JSON Lines, e.g. omni-ridge's
    /// output or another detector's) instead of detecting them: each frame record's image (its
    /// `path`, resolved against the header's frames_dir) is searched for the board, its
    /// `stripe` points used. Frames without a `stripe` field are errors.
    #[arg(long)]
    stripes: Option<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
    /// Stripe detector: widest stripe (px) at full resolution.
    #[arg(long, default_value_t = 12.0, allow_negative_numbers = true)]
    max_width: f64,
    /// Stripe detector: coarsest scale (1, 2, 4, 8, 16) at which wider stripes are searched.
    #[arg(long, default_value_t = 8, value_name = "N")]
    max_scale: u32,
    /// Stripe detector: the lens's blur (Gaussian PSF σ, px), whose pull on curved stripes is
    /// removed and whose shift of a lopsided laser's peak is undone [default: from the camera
    /// file (its lens_blur_px, else its optics), else measured on each frame's stripes, as
    /// omni-ridge].
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    optics_blur: Option<f64>,
    /// Stripe detector: the laser's cross-section, if known (a core with a one-sided tail
    /// holding SHARE of the light, LENGTH core σ long; as omni-ridge): the stripe's pieces
    /// between the board's squares, too short for their own top shape, are then led to the
    /// sheet's peak too, and so are its clipped points on the white squares, by the width of
    /// its unclipped profiles on the black ones.
    #[arg(long, value_name = "SHARE,LENGTH")]
    laser_tail: Option<omni_model::LaserProfile>,
    /// Stripe detector: the laser lights one point per image column (or row), as in an
    /// ordinary triangulation sensor; stripes sharing a column with one at least twice as
    /// bright are dropped as its reflections (as omni-ridge).
    #[arg(long, value_name = "LINE", value_parser = parse_scan_lines)]
    one_stripe_per: Option<omni_vision::stripe::ScanLines>,
    /// Keep stripe points up to this far outside the printed pattern (mm; negative: inside).
    /// Default: the board file's margin_mm, its white border, where a flat board carries the
    /// stripe as well as on its squares.
    #[arg(long, allow_negative_numbers = true)]
    margin_mm: Option<f64>,
    /// Drop stripe points closer than this (px, as imaged) to a square's edge, where the stripe
    /// falls on a white and a black square at once and its centre moves, or to the board's own
    /// edge (the pattern widened by the margin) (0: keep them).
    #[arg(long, default_value_t = 3.0, value_name = "PX", allow_negative_numbers = true)]
    edge_clearance_px: f64,
    /// Fewest stripe points on the board for a frame to be used.
    #[arg(long, default_value_t = 30)]
    min_points: usize,
    /// Fewest corners of a (partial) board.
    #[arg(long, default_value_t = 12)]
    min_corners: usize,
    /// The laser's id in scanner.json (frames list it in `lasers`).
    #[arg(long, default_value_t = 0)]
    laser_id: u32,
    /// Write the report (JSON, format omniscan.fixed_plane_report) here as well.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write every board point here (JSON Lines: frame, x y z mm, u v px, residual mm, inlier).
    #[arg(long)]
    points: Option<PathBuf>,
    /// Refuse a plane whose residual RMS (mm, its inliers about it) exceeds this: the points are
    /// not one laser's on the boards (the wrong channel or colour, stripes of another scan).
    /// A sound rig gives hundredths to a few tenths.
    #[arg(long, default_value_t = 2.0, value_name = "MM")]
    max_residual_mm: f64,
    /// Output scanner.json (`-` = stdout), written atomically.
    #[arg(short, long, default_value = "scanner.json")]
    output: PathBuf,
}

#[derive(Args)]
#[command(group(ArgGroup::new("pose_source").required(true).args(["pose_image", "board_corners", "board_poses"])))]
#[command(after_help = "Board poses come from exactly one of --pose-image (the rig boards are found in the ambient \
    pose image and posed with the camera), --board-corners (their corner pixels given) or --board-poses (known \
    poses).\n\
    Frames belong to rig placement 0 unless their record has an integer field `placement`.\n\n\
    Example:\n  omni-calib-plane fit --camera camera.json --rig rig.json --pose-image rig/pose.png --stripes stripes.jsonl -o scanner.json")]
struct FitArgs {
    /// Calibrated receiver (camera.json).
    #[arg(long)]
    camera: PathBuf,
    /// The rig's boards (rig.json, format omniscan.rig).
    #[arg(long)]
    rig: PathBuf,
    /// Ambient (lasers off) image of the rig, in which the boards are found (PNG 8/16-bit, JPEG).
    /// Give several images of the unmoved rig (`--pose-image a.png b.png …`) to average them
    /// pixel by pixel first: the sensor noise falls as 1/√n and the board poses improve.
    #[arg(long, num_args = 1..)]
    pose_image: Vec<PathBuf>,
    /// Corner pixels of the rig boards in the pose image (format omniscan.board_corners).
    #[arg(long)]
    board_corners: Option<PathBuf>,
    /// Known board poses (format omniscan.board_poses).
    #[arg(long)]
    board_poses: Option<PathBuf>,
    /// The omni-ridge stream of the laser frames (`-` = stdin).
    #[arg(long)]
    stripes: PathBuf,
    /// Starting transmitter (scanner.json); default: the paper's ideal build.
    #[arg(long)]
    initial: Option<PathBuf>,
    /// Fewest board points a frame's laser needs to be used.
    #[arg(long, default_value_t = 20, allow_negative_numbers = true)]
    min_points: usize,
    /// Drop board points farther than this (mm) from the initial model's light plane before
    /// fitting (e.g. checkerboard edges in frames without ambient subtraction); needs an
    /// --initial model that close to the build.
    #[arg(long, allow_negative_numbers = true)]
    gate_mm: Option<f64>,
    /// Fewest visible corners to pose a board.
    #[arg(long, default_value_t = 6, allow_negative_numbers = true)]
    min_corners: usize,
    /// Refuse a --stripes stream without its final status record (cut short upstream);
    /// without it the tool warns and fits what it got.
    #[arg(long)]
    strict: bool,
    /// Refuse a fit whose model residual RMS (mm) exceeds this: the stripes do not belong to
    /// these boards (another scan's stream, the wrong poses). A sound rig gives a few tenths.
    #[arg(long, default_value_t = 2.0, value_name = "MM")]
    max_residual_mm: f64,
    /// Output scanner.json (`-` = stdout), written atomically.
    #[arg(short, long, default_value = "scanner.json")]
    output: PathBuf,
}

#[derive(Args)]
#[command(after_help = "Example:\n  omni-calib-plane table --scanner scanner.json --alpha 0:30:0.5 --laser 0 --json")]
struct TableArgs {
    /// Calibrated scanner.json.
    #[arg(long)]
    scanner: PathBuf,
    /// Mirror angles within a facet, degrees: START:STOP:STEP (stop included) or one angle.
    #[arg(long, default_value = "0:30:1", allow_hyphen_values = true)]
    alpha: String,
    /// Only this laser (default: all).
    #[arg(long, allow_negative_numbers = true)]
    laser: Option<usize>,
    /// Facet facing laser 0.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    facet: u32,
    /// JSON output (an array of rows) instead of a text table.
    #[arg(long)]
    json: bool,
}

fn main() -> std::process::ExitCode {
    omni_cli::main("omni-calib-plane", || match omni_cli::parse_args::<Cli>()?.command {
        Command::Fit(a) => fit(&a),
        Command::Table(a) => table(&a),
        Command::Fixed(a) => fixed(&a),
        Command::Tail(a) => tail(&a),
    })
}

fn name(p: &Path) -> String {
    io::display_name(p, "stdin")
}

fn fit(a: &FitArgs) -> CliResult {
    omni_cli::positive("--max-residual-mm", a.max_residual_mm)?;
    let (_, camera) = CameraFile::load(&a.camera)?;
    let rig: RigFile = read_doc(&a.rig)?;
    rig.validate().map_err(|m| CliError::new(format!("{}: {m}", name(&a.rig))))?;
    let pose_image = a.pose_image.first();
    let boards = match (pose_image, &a.board_corners, &a.board_poses) {
        (Some(path), _, _) => {
            let images = a
                .pose_image
                .iter()
                .map(|p| omni_vision::corners::load_gray(p).map_err(CliError::new))
                .collect::<Result<Vec<_>, _>>()?;
            let image = inputs::mean_image(&images).map_err(|m| CliError::new(format!("--pose-image: {m}")))?;
            inputs::boards_from_pose_image(camera.as_ref(), &rig, &image, a.min_corners)
                .map_err(|m| CliError::new(format!("{}: {m}", name(path))))?
        }
        (None, Some(path), _) => {
            let corners: BoardCornersFile = read_doc(path)?;
            inputs::boards_from_corners(camera.as_ref(), &rig, &corners, a.min_corners)
                .map_err(|m| CliError::new(format!("{}: {m}", name(path))))?
        }
        (None, None, Some(path)) => {
            let poses: BoardPosesFile = read_doc(path)?;
            inputs::boards_from_poses(&rig, &poses).map_err(|m| CliError::new(format!("{}: {m}", name(path))))?
        }
        (None, None, None) => return Err(CliError::usage("give --pose-image, --board-corners or --board-poses")),
    };
    let initial = match &a.initial {
        Some(p) => ScannerFile::load_polygon(p)?.1.params().clone(),
        None => TransmitterParams::paper(),
    };
    let mut reader = StreamReader::new(io::open_input(&a.stripes)?, name(&a.stripes));
    let frames = inputs::read_stripe_frames(&mut reader)?;
    if reader.cut_short() {
        let msg = reader.cut_short_message();
        if a.strict {
            return Err(CliError::new(format!("{msg}; refused with --strict")));
        }
        omni_cli::warn("omni-calib-plane", &format!("{msg}; fitting the frames it has"));
    }
    if a.gate_mm.is_some_and(|g| !(g > 0.0)) {
        return Err(CliError::usage("--gate-mm must be positive"));
    }
    let opts = PlaneCalibOptions { min_points_per_frame: a.min_points, gate_mm: a.gate_mm, ..Default::default() };
    let (placed, pose_reports): (Vec<_>, Vec<_>) = boards.into_iter().unzip();
    let cal = plane::calibrate_planes(camera.as_ref(), &placed, &frames, &initial, &opts)
        .map_err(|m| CliError::new(format!("{}: {m}", name(&a.stripes))))?;
    let residual = cal.report.model.residual_rms_mm;
    if !(residual <= a.max_residual_mm) {
        return Err(CliError::new(format!(
            "{}: the model's residual RMS is {residual:.3} mm, above --max-residual-mm {}: do these stripes belong to these boards (another scan's stream, the wrong poses)?",
            name(&a.stripes),
            a.max_residual_mm
        )));
    }
    let mut report = serde_json::to_value(&cal.report)?;
    report["boards"] = serde_json::to_value(&pose_reports)?;
    report["inputs"] = serde_json::json!({
        "camera": name(&a.camera),
        "rig": name(&a.rig),
        "stripes": name(&a.stripes),
        "initial": a.initial.as_deref().map(name),
        "gate_mm": a.gate_mm,
    });
    let failed = cal.report.model.board_pose_steps_failed;
    if failed > 0 {
        omni_cli::warn(
            "omni-calib-plane",
            &format!(
                "{failed} of the boards' pose steps gave no fit: the parameters' σ leave out that part of the boards' pose errors"
            ),
        );
    }
    if let Some(loose) = plane::loosely_determined(&cal.report.model.parameters, 1.0) {
        omni_cli::warn(
            "omni-calib-plane",
            &format!(
                "the frames determine the transmitter loosely: {loose} (σ above {} mm or {}°): its light planes are good within the rig's mirror angles and extrapolated beyond them; for every angle, take stripe frames over each facet's whole sweep",
                plane::LOOSE_STD_MM,
                plane::LOOSE_STD_DEG
            ),
        );
    }
    if let Some(unseen) = unseen_on_the_rig(&cal.report.model.fixed) {
        omni_cli::warn(
            "omni-calib-plane",
            &format!(
                "{unseen}: no stripe on the rig, kept at their initial values: frames taken with them triangulate through uncalibrated light planes; calibrate with frames of every facet and laser the scans use"
            ),
        );
    }
    let mut out = ScannerFile::new(cal.transmitter);
    out.report = Some(report);
    write_doc(&a.output, &out)?;
    if a.output != Path::new("-") {
        let frames_used = cal.report.frames.iter().map(|f| f.seq).collect::<std::collections::BTreeSet<_>>().len();
        eprintln!(
            "omni-calib-plane: {} of {} frames used ({} light planes, one per frame and laser), model residual RMS {:.3} mm, frame-plane RMS {:.3} mm, {} rejected; wrote {}",
            frames_used,
            cal.report.frames_total,
            cal.report.observations_used,
            cal.report.model.residual_rms_mm,
            cal.report.frame_plane_rms_mm,
            cal.report.rejected.len(),
            a.output.display()
        );
    }
    Ok(())
}

/// The facets and lasers the fit kept at their initial values because no rig frame showed
/// them (the report's `fixed` entries `facet_errors[k]` / `lasers[j]` … "not observed"), as
/// "facets 1–11, laser 1"; `None` if every one was seen.
fn unseen_on_the_rig(fixed: &[String]) -> Option<String> {
    let (facets, lasers) = omni_formats::unobserved_in(fixed.iter().map(String::as_str));
    let named = |one: &str, many: &str, k: Vec<u32>| -> Option<String> {
        let mut runs: Vec<String> = Vec::new();
        let mut i = 0;
        while i < k.len() {
            let mut j = i;
            while j + 1 < k.len() && k[j + 1] == k[j] + 1 {
                j += 1;
            }
            runs.push(if j > i { format!("{}–{}", k[i], k[j]) } else { k[i].to_string() });
            i = j + 1;
        }
        let word = if k.len() == 1 { one } else { many };
        (!k.is_empty()).then(|| format!("{word} {}", runs.join(", ")))
    };
    let parts: Vec<String> =
        [named("facet", "facets", facets), named("laser", "lasers", lasers)].into_iter().flatten().collect();
    (!parts.is_empty()).then(|| parts.join(", "))
}

fn table(a: &TableArgs) -> CliResult {
    let alphas = plane::parse_alpha_range(&a.alpha).map_err(|m| CliError::usage(format!("--alpha: {m}")))?;
    let (_, tx) = ScannerFile::load_polygon(&a.scanner)?;
    // Its only refusals are a --facet or --laser the model does not have: usage errors.
    let rows = plane::light_plane_table(tx.params(), &alphas, a.facet, a.laser)
        .map_err(|m| CliError::usage(format!("{}: {m}", name(&a.scanner))))?;
    let mut out = String::new();
    if a.json {
        out = serde_json::to_string_pretty(&rows)?;
        out.push('\n');
    } else {
        out.push_str(&format!(
            "{:>9} {:>5} {:>5} {:>11} {:>11} {:>11} {:>12} {:>11} {:>13}\n",
            "alpha_deg", "facet", "laser", "normal_x", "normal_y", "normal_z", "offset_mm", "slope", "intercept_mm"
        ));
        for r in &rows {
            out.push_str(&format!(
                "{:>9.3} {:>5} {:>5} {:>11.7} {:>11.7} {:>11.7} {:>12.4} {:>11.7} {:>13.4}\n",
                r.alpha_deg,
                r.facet,
                r.laser,
                r.normal[0],
                r.normal[1],
                r.normal[2],
                r.offset_mm,
                r.slope,
                r.intercept_mm
            ));
        }
    }
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(out.as_bytes()).and_then(|_| stdout.flush()).map_err(omni_cli::stdout_error)
}

/// Each frame's stripe centres (px).
type Stripes = Vec<Vec<[f64; 2]>>;

/// The frames of a stripe stream: each frame record's image path and stripe centres (px).
fn read_stripe_stream(path: &Path) -> CliResult<(Vec<PathBuf>, Stripes)> {
    use omni_formats::stream::Record;
    let mut reader = StreamReader::open(path)?;
    let mut frames_dir: Option<String> = None;
    let (mut paths, mut stripes) = (Vec::new(), Vec::new());
    while let Some(record) = reader.next_record()? {
        match record {
            Record::Header(h) => frames_dir = h.frames_dir,
            Record::Frame(f) => {
                let Some(stripe) = &f.stripe else {
                    return Err(CliError::new(format!(
                        "{}: line {} (frame {}): no stripe field: run a stripe detector on the frames first",
                        name(path),
                        reader.line(),
                        f.seq
                    )));
                };
                paths.push(f.resolve_path(frames_dir.as_deref(), &f.path));
                stripes.push(stripe.iter().map(|p| [p.u, p.v]).collect());
            }
            _ => {}
        }
    }
    Ok((paths, stripes))
}

fn parse_scan_lines(s: &str) -> Result<omni_vision::stripe::ScanLines, String> {
    s.parse()
}

/// The frames given: files as they are, directories' images in name order.
fn expand_frames(paths: &[PathBuf]) -> CliResult<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| CliError::new(format!("{}: {e}", p.display())))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.extension()
                        .and_then(|x| x.to_str())
                        .is_some_and(|x| ["png", "jpg", "jpeg", "pgm"].contains(&x.to_ascii_lowercase().as_str()))
                })
                .collect();
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

fn fixed(a: &FixedArgs) -> CliResult {
    use omni_calib::fixed_plane::{self, DetectOptions, FixedPlaneOptions};
    use omni_vision::colour::ColourSpec;
    let ridge = omni_vision::stripe::RidgeParams {
        threshold: a.read.threshold,
        max_width: a.max_width,
        max_scale: a.max_scale,
        optics_blur_px: a.optics_blur,
        laser_profile: a.laser_tail,
        one_stripe_per: a.one_stripe_per,
        ..Default::default()
    };
    ridge.validate().map_err(CliError::usage)?;
    if a.margin_mm.is_some_and(|m| !m.is_finite()) {
        return Err(CliError::usage("--margin-mm must be a finite number"));
    }
    if !(a.edge_clearance_px.is_finite() && a.edge_clearance_px >= 0.0) {
        return Err(CliError::usage("--edge-clearance-px must be a finite number >= 0"));
    }
    if a.min_points < 3 {
        return Err(CliError::usage("--min-points must be at least 3"));
    }
    if a.min_corners < 4 {
        return Err(CliError::usage("--min-corners must be at least 4"));
    }
    omni_cli::positive("--max-residual-mm", a.max_residual_mm)?;
    let channel = a.read.channel()?;
    let (camera_file, camera) = CameraFile::load(&a.camera)?;
    let ridge = ridge.with_lens_blur_of(&camera_file).map_err(|e| format!("{}: {e}", a.camera.display()))?;
    let board: omni_formats::BoardFile = read_doc(&a.board)?;
    let margin_mm = a.margin_mm.unwrap_or(board.margin_mm);
    let (paths, given) = match &a.stripes {
        Some(path) => {
            let (paths, stripes) = read_stripe_stream(path)?;
            (paths, Some(stripes))
        }
        None => (expand_frames(&a.frames)?, None),
    };
    if paths.is_empty() {
        return Err(CliError::new("no frames given (the directories hold no png/jpg/pgm)"));
    }
    let detect = DetectOptions {
        inner_cols: board.inner_cols,
        inner_rows: board.inner_rows,
        square_mm: board.square_mm,
        min_corners: a.min_corners,
        colour: ColourSpec { channel, bayer: None, sites: false },
        ridge,
    };
    let frames = fixed_plane::detect_frames(&paths, &detect, given.as_deref()).map_err(|m| {
        if m.starts_with("the board file says") {
            CliError::new(format!("{}: {m}", name(&a.board)))
        } else {
            CliError::new(grey_hint(m))
        }
    })?;
    let opts = FixedPlaneOptions {
        square_mm: board.square_mm,
        margin_mm,
        edge_clearance_px: a.edge_clearance_px,
        min_points: a.min_points,
        seed: 1,
    };
    let fit = fixed_plane::fit_fixed_plane(camera.as_ref(), &frames, &opts).map_err(CliError::new)?;
    if !(fit.report.rms_mm <= a.max_residual_mm) {
        let why = match &a.stripes {
            Some(path) => format!("do the stripes of {} belong to these frames?", name(path)),
            None => format!("is the laser read right (read as {}: --laser, --channel)?", detect.colour.channel),
        };
        return Err(CliError::new(format!(
            "the plane's residual RMS is {:.3} mm, above --max-residual-mm {}: {why}",
            fit.report.rms_mm, a.max_residual_mm
        )));
    }
    let mut report = serde_json::to_value(&fit.report)?;
    report["inputs"] = serde_json::json!({
        "camera": name(&a.camera),
        "board": name(&a.board),
        "frames": paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "channel": detect.colour.channel.to_string(),
        "stripes": a.stripes.as_deref().map(name),
        "margin_mm": margin_mm,
        "edge_clearance_px": a.edge_clearance_px,
        "min_points": a.min_points,
        // The lens's blur the stripe detector removed from curved stripes; null: measured on each
        // frame's stripes (or the centres came from --stripes).
        "optics_blur_px": if a.stripes.is_some() { None } else { ridge.optics_blur_px },
        // The laser's cross-section the stripe detector was told ([share, length]); null: none.
        "laser_tail": ridge.laser_profile.filter(|_| a.stripes.is_none()).map(|p| [p.tail_weight(), p.tail_length()]),
    });
    let mut params = omni_model::FixedPlanesParams::single(&fit.plane);
    params.planes[0].laser = a.laser_id;
    if let Some(path) = &a.report {
        let mut doc = serde_json::json!({"format": "omniscan.fixed_plane_report", "version": 1});
        doc["report"] = report.clone();
        write_doc(path, &doc)?;
    }
    if let Some(path) = &a.points {
        io::write_atomic(path, |w| {
            for f in &fit.frames {
                for ((p, px), inl) in f.points.iter().zip(&f.pixels).zip(&f.inliers) {
                    let line = serde_json::json!({"frame": f.name, "xyz_mm": [p.x, p.y, p.z], "px": px,
                        "residual_mm": fit.plane.signed_distance(p), "inlier": inl});
                    writeln!(w, "{line}")?;
                }
            }
            Ok(())
        })?;
    }
    let mut out = ScannerFile::new(params);
    out.report = Some(report);
    write_doc(&a.output, &out)?;
    warn_saturated(&fit.report);
    warn_inconsistent(&fit.report);
    warn_border_off_the_plane(&fit.report, margin_mm);
    let source = if a.margin_mm.is_some() { "--margin-mm" } else { "margin_mm of the board file" };
    let table = format!(
        "board: {} × {} inner corners, {} mm squares; stripe points kept up to {margin_mm} mm beyond the printed pattern ({source})\n{}",
        board.inner_cols,
        board.inner_rows,
        board.square_mm,
        fixed_table(&fit.report)
    );
    use std::io::Write;
    if a.output == Path::new("-") {
        eprint!("{table}");
    } else {
        let mut stdout = std::io::stdout().lock();
        stdout.write_all(table.as_bytes()).and_then(|_| stdout.flush()).map_err(omni_cli::stdout_error)?;
    }
    Ok(())
}

fn tail(a: &TailArgs) -> CliResult {
    use omni_calib::laser_tail::{self, TailOptions};
    use omni_vision::colour::ColourSpec;
    let channel = a.read.channel()?;
    let mut ridge = omni_vision::stripe::RidgeParams {
        threshold: a.read.threshold,
        max_width: a.max_width,
        optics_blur_px: a.optics_blur,
        ..Default::default()
    };
    ridge.validate().map_err(CliError::usage)?;
    if a.min_profiles < 5 {
        return Err(CliError::usage("--min-profiles must be at least 5"));
    }
    let mut mirror = None;
    if let Some(path) = &a.camera {
        let (camera_file, camera) = CameraFile::load(path)?;
        ridge = ridge.with_lens_blur_of(&camera_file).map_err(|e| format!("{}: {e}", path.display()))?;
        mirror = Some(camera.mirror_circle());
    }
    let paths = expand_frames(&a.frames)?;
    if paths.is_empty() {
        return Err(CliError::new("no frames given (the directories hold no png/jpg/pgm)"));
    }
    let opts = TailOptions { blur_px: ridge.optics_blur_px.unwrap_or(0.0), min_profiles: a.min_profiles, mirror };
    let colour = ColourSpec { channel, bayer: None, sites: false };
    let report = laser_tail::measure_frames(&paths, &colour, &ridge, &opts).map_err(|m| CliError::new(grey_hint(m)))?;
    if let Some(path) = &a.report {
        let mut doc = serde_json::json!({"format": "omniscan.laser_tail_report", "version": 1});
        doc["report"] = serde_json::to_value(&report)?;
        doc["report"]["inputs"] = serde_json::json!({
            "channel": colour.channel.to_string(),
            "optics_blur_px": opts.blur_px,
            "min_profiles": a.min_profiles,
        });
        write_doc(path, &doc)?;
    }
    let argument = format!("{:.2},{:.1}", report.tail_weight, report.tail_length);
    argument
        .parse::<omni_model::LaserProfile>()
        .map_err(|e| CliError::new(format!("the tail measured, {argument}: {e}")))?;
    let table = tail_table(&report, &argument);
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    let out = if a.quiet {
        eprint!("{table}");
        format!("{argument}\n")
    } else {
        table
    };
    stdout.write_all(out.as_bytes()).and_then(|_| stdout.flush()).map_err(omni_cli::stdout_error)?;
    Ok(())
}

/// A frame-reading error, with this tool's way to read a grey frame where the laser's colour
/// was asked of one (the reader's own hint names omni-ridge's raw-mosaic option).
fn grey_hint(message: String) -> String {
    match message.split_once(" (a raw Bayer mosaic needs --bayer ORDER)") {
        Some((head, tail)) if message.contains("the frame is grey") => {
            format!("{head} (read a grey frame with --channel luma){tail}")
        }
        _ => message,
    }
}

/// The human table of a tail measurement, ending with the `--laser-tail` argument.
fn tail_table(r: &omni_calib::laser_tail::TailReport, argument: &str) -> String {
    let mut t = format!(
        "{:<24} {:>8} {:>8} {:>8} {:>14} {:>16} {:>14} {:>9} {:>9}\n",
        "frame", "profiles", "sigma_px", "fwhm_px", "share ± σ", "length ± σ", "tail towards", "residual", "gaussian"
    );
    for f in &r.frames {
        let towards = match f.tail_direction {
            Some([x, y]) => format!("({x:+.2}, {y:+.2})"),
            None if f.side > 0.0 => "outwards".into(),
            None => "inwards".into(),
        };
        t += &format!(
            "{:<24} {:>8} {:>8.2} {:>8.2} {:>6.3} ± {:<5.3} {:>7.2} ± {:<6.2} {:>14} {:>9.4} {:>9.4}\n",
            file_name(&f.name),
            f.profiles,
            f.core_sigma_px,
            f.fwhm_px,
            f.tail_weight,
            f.tail_weight_sigma,
            f.tail_length,
            f.tail_length_sigma,
            towards,
            f.residual_rms,
            f.gaussian_residual_rms
        );
    }
    for s in &r.skipped {
        t += &format!("left out {}: {}\n", file_name(&s.name), s.reason);
    }
    t += &format!(
        "laser tail from {} of {} frames: share {:.3} ({:.3}-{:.3}), length {:.2} core sigma ({:.2}-{:.2}); give it as --laser-tail {argument}\n",
        r.frames.len(),
        r.frames_total,
        r.tail_weight,
        r.tail_weight_range[0],
        r.tail_weight_range[1],
        r.tail_length,
        r.tail_length_range[0],
        r.tail_length_range[1]
    );
    t
}

/// A leave-one-frame-out RMS above this multiple of the in-sample RMS draws a warning: with
/// hundreds of points a frame, a frame's own points barely move the plane, so the two agree
/// unless the frames disagree (sound rigs: 1.1-1.3, the real hand-held frames and the rendered
/// fixed plane alike).
const LEAVE_ONE_OUT_WARNING_RATIO: f64 = 2.0;

/// Warns, in one line, when the frames disagree about the plane (the leave-one-frame-out RMS
/// well above the in-sample RMS), naming the frames that disagree most: a frame whose stripe is
/// not this laser's (a reflection, another frame's stripes), whose board pose is off, or a rig
/// that moved between frames.
fn warn_inconsistent(r: &omni_calib::fixed_plane::FixedPlaneReport) {
    if !(r.leave_one_out_rms_mm > LEAVE_ONE_OUT_WARNING_RATIO * r.rms_mm) {
        return;
    }
    let mut frames: Vec<&omni_calib::fixed_plane::FrameReport> = r.frames.iter().collect();
    frames.sort_by(|a, b| b.leave_one_out_rms_mm.total_cmp(&a.leave_one_out_rms_mm));
    let worst: Vec<String> =
        frames.iter().take(3).map(|f| format!("{} {:.3} mm", file_name(&f.name), f.leave_one_out_rms_mm)).collect();
    omni_cli::warn(
        "omni-calib-plane",
        &format!(
            "the frames disagree about the plane: leave-one-frame-out RMS {:.3} mm, {:.1} x the residual RMS {:.3} mm \
             (most: {}); check those frames' stripes and board poses, and that the laser did not move",
            r.leave_one_out_rms_mm,
            r.leave_one_out_rms_mm / r.rms_mm,
            r.rms_mm,
            worst.join(", ")
        ),
    );
}

/// Warns, in one line, of the frames whose stripe points on the board's white border are mostly
/// off the plane (the robust fit leaves them out): the border kept (`margin_mm`) is wider than
/// the board's, whose points beyond its edge lie on whatever is behind it, or print on the
/// border, its curl or a reflection of the stripe moves them. Their median distance tells
/// which.
fn warn_border_off_the_plane(r: &omni_calib::fixed_plane::FixedPlaneReport, margin_mm: f64) {
    let off: Vec<String> = r
        .frames
        .iter()
        .filter(|f| f.border_points >= BORDER_WARNING_MIN_POINTS && 2 * f.border_outliers > f.border_points)
        .map(|f| {
            let off = f.border_outlier_median_mm.map_or(String::new(), |d| format!(", {d:.1} mm off"));
            format!("{} {} of {}{off}", file_name(&f.name), f.border_outliers, f.border_points)
        })
        .collect();
    if off.is_empty() {
        return;
    }
    omni_cli::warn(
        "omni-calib-plane",
        &format!(
            "{} of {} frames have most of their stripe points on the board's border off the plane ({}; median distance; the fit leaves them out): is the border flat and blank as far as the {margin_mm} mm kept (margin_mm, --margin-mm), with no reflection of the stripe on it?",
            off.len(),
            r.frames.len(),
            off.join(", ")
        ),
    );
}

/// Fewest border points of a frame that [`warn_border_off_the_plane`] judges.
const BORDER_WARNING_MIN_POINTS: usize = 20;

/// More than this share of a frame's stripe points on the board saturated draws a warning.
const SATURATED_WARNING_SHARE: f64 = 0.25;

/// Warns, in one line, of the frames whose stripe on the board is largely saturated: a clipped
/// stripe is read at its plateau's middle, which lies towards a lopsided laser's tail (in the
/// simulator 0.06-0.4 px for a real-shaped 4 px stripe clipped at 1/2 to 1/10 of its peak;
/// docs/DECISIONS.md).
fn warn_saturated(r: &omni_calib::fixed_plane::FixedPlaneReport) {
    let saturated: Vec<String> = r
        .frames
        .iter()
        .filter_map(|f| {
            let share = f.saturated_points? as f64 / f.board_points.max(1) as f64;
            (share > SATURATED_WARNING_SHARE).then(|| format!("{} {:.0} %", file_name(&f.name), 100.0 * share))
        })
        .collect();
    if !saturated.is_empty() {
        omni_cli::warn(
            "omni-calib-plane",
            &format!(
                "{} of {} frames have more than {:.0} % of the stripe's points on the board saturated ({}); a \
                 clipped stripe is read towards a lopsided laser's tail, by up to a few tenths of a px: for the \
                 best plane lower the exposure or the laser's power",
                saturated.len(),
                r.frames.len(),
                100.0 * SATURATED_WARNING_SHARE,
                saturated.join(", ")
            ),
        );
    }
}

/// A frame's file name without its directories, for the table and warnings.
fn file_name(path: &str) -> String {
    Path::new(path).file_name().map_or(path.to_string(), |n| n.to_string_lossy().into_owned())
}

/// The human table of a fixed-plane fit.
fn fixed_table(r: &omni_calib::fixed_plane::FixedPlaneReport) -> String {
    let mut t = String::new();
    t.push_str(&format!(
        "{:<24} {:>7} {:>9} {:>8} {:>8} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
        "frame",
        "corners",
        "corner_px",
        "dist_mm",
        "points",
        "inliers",
        "rms_mm",
        "mean_mm",
        "line_mm",
        "line_px",
        "loo_mm"
    ));
    for f in &r.frames {
        let short = file_name(&f.name);
        t.push_str(&format!(
            "{:<24} {:>7} {:>9.3} {:>8.1} {:>8} {:>8} {:>9.4} {:>9.4} {:>9.4} {:>9.3} {:>9.4}\n",
            short,
            f.corners,
            f.corner_rms_px,
            f.board_distance_mm,
            f.board_points,
            f.inliers,
            f.residual_rms_mm,
            f.residual_mean_mm,
            f.straightness_mm,
            f.straightness_px,
            f.leave_one_out_rms_mm
        ));
    }
    for s in &r.skipped {
        t.push_str(&format!("skipped {}: {}\n", s.name, s.reason));
    }
    let p = &r.plane;
    t.push_str(&format!(
        "plane: normal ({:.6}, {:.6}, {:.6}), distance {:.3} mm; {} of {} frames, {} of {} points inliers\n",
        p.normal[0],
        p.normal[1],
        p.normal[2],
        p.distance_mm,
        r.frames.len(),
        r.frames_total,
        r.inliers,
        r.points
    ));
    t.push_str(&format!(
        "residual RMS {:.4} mm (robust sigma {:.4} mm), leave-one-frame-out RMS {:.4} mm ({:.2} x)\n",
        r.rms_mm,
        r.robust_sigma_mm,
        r.leave_one_out_rms_mm,
        r.leave_one_out_rms_mm / r.rms_mm
    ));
    t.push_str(&format!(
        "uncertainty: normal {:.4} deg, distance {:.4} mm, at the centroid {:.4} mm (fit); {:.4} deg, {:.4} mm, {:.4} mm (jackknife over frames)\n",
        p.normal_sigma_deg,
        p.distance_sigma_mm,
        p.centroid_sigma_mm,
        p.jackknife_normal_sigma_deg,
        p.jackknife_distance_sigma_mm,
        p.jackknife_centroid_sigma_mm
    ));
    t
}

#[cfg(test)]
mod tests {
    use super::unseen_on_the_rig;

    #[test]
    fn facets_and_lasers_the_rig_never_showed_are_named_as_runs() {
        let mut fixed: Vec<String> =
            (1..12).map(|k| format!("facet_errors[{k}]: facet not observed, kept at its initial value")).collect();
        fixed.push("lasers[1]: laser not observed, kept at its initial value".into());
        fixed.push("polygon.circumradius_mm: nominal (radius errors are fitted per facet)".into());
        assert_eq!(unseen_on_the_rig(&fixed).as_deref(), Some("facets 1–11, laser 1"));
        fixed.remove(4);
        assert_eq!(unseen_on_the_rig(&fixed).as_deref(), Some("facets 1–4, 6–11, laser 1"));
        assert_eq!(unseen_on_the_rig(&fixed[fixed.len() - 1..]), None);
    }
}
