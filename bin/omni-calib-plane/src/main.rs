//! omni-calib-plane: calibrate the swept light planes (the transmitter) from laser stripes on
//! posed checkerboards, and print the light-plane table of a calibrated scanner.

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
        at once and writes scanner.json. `table` prints the light plane of any mirror angle.",
    after_help = "Examples:\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --pose-image rig/pose.png --stripes stripes.jsonl -o scanner.json\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --pose-image rig/pose*.png --stripes stripes.jsonl -o scanner.json   # several pose images, averaged\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --board-corners corners.json --stripes stripes.jsonl -o scanner.json\n  \
        omni-calib-plane fit --camera camera.json --rig rig.json --board-poses poses.json --stripes - --initial nominal.json -o scanner.json\n  \
        omni-calib-plane table --scanner scanner.json --alpha 0:30:1\n  \
        omni-calib-plane table --scanner scanner.json --alpha 0:30:0.5 --laser 0 --facet 3 --json"
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
}

#[derive(Args)]
#[command(group(ArgGroup::new("pose_source").required(true).args(["pose_image", "board_corners", "board_poses"])))]
#[command(after_help = "Board poses come from exactly one of --pose-image (the rig boards are found in the ambient \
    pose image and posed with the camera), --board-corners (their corner pixels given) or --board-poses (known \
    poses).\n\
    Frames belong to rig placement 0 unless their record has an integer field `placement`.")]
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
    /// Output scanner.json (`-` = stdout), written atomically.
    #[arg(short, long, default_value = "scanner.json")]
    output: PathBuf,
}

#[derive(Args)]
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
    omni_cli::main("omni-calib-plane", || match Cli::parse().command {
        Command::Fit(a) => fit(&a),
        Command::Table(a) => table(&a),
    })
}

fn name(p: &Path) -> String {
    io::display_name(p, "stdin")
}

fn fit(a: &FitArgs) -> CliResult {
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
    let mut report = serde_json::to_value(&cal.report)?;
    report["boards"] = serde_json::to_value(&pose_reports)?;
    report["inputs"] = serde_json::json!({
        "camera": name(&a.camera),
        "rig": name(&a.rig),
        "stripes": name(&a.stripes),
        "initial": a.initial.as_deref().map(name),
        "gate_mm": a.gate_mm,
    });
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

fn table(a: &TableArgs) -> CliResult {
    let alphas = plane::parse_alpha_range(&a.alpha).map_err(|m| CliError::usage(format!("--alpha: {m}")))?;
    let (_, tx) = ScannerFile::load_polygon(&a.scanner)?;
    let rows = plane::light_plane_table(tx.params(), &alphas, a.facet, a.laser)
        .map_err(|m| CliError::new(format!("{}: {m}", name(&a.scanner))))?;
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
    stdout.write_all(out.as_bytes())?;
    stdout.flush()?;
    Ok(())
}
