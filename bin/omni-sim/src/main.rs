//! omni-sim: the virtual omnidirectional line-laser sensor (see the `omni_simulator` crate).

use clap::{Parser, Subcommand, ValueEnum};
use omni_cli::{CliError, CliResult};
use omni_formats::{BoardFile, CameraFile, CameraSpec, ScannerFile, write_doc};
use omni_simulator::{
    BenchObject, BoardPose, Imaging, Imperfections, Optics, RenderOptions, RenderedFrame, Rig, Scene, Sensor, Sweep,
    check_boards_visible, paper_bench, paper_preset, parse_angles, random_board_poses, render_board_image,
    render_rig_pose_image, render_sweep, write_manifest, write_truth,
};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const AFTER_HELP: &str = "\
The simulated sensor is the paper's prototype: hyperbolic mirror a² = 1248.2060 mm², b² = 351.7940 mm²
(c = 40 mm), rim radius 25 mm, seen by a 1024 × 1024 px camera with f = 1950 px (a 9.07 mm lens on
4.65 µm pixels) at the mirror's lower focus; a 12-facet polygon mirror of circumradius R = 20 mm turning
about the y axis 120 mm below the camera centre, two line lasers (180° fans) on either side.

The realistic sensor (the default): industrial 8-bit monochrome camera, full well 10 000 e-, read noise
6 e-, gamma 1, behind an F/4 lens (650 nm laser, 4.65 µm pixels, 1.5 px of defocus; camera.json's
`optics`), the laser imaged coherently through the lens pupil, so its speckle and blur follow from the
optics; laser sheet 0.5 mm FWHM; a mid-bright room (white ≈ 77/255 in laser frames). --ideal gives
the idealised sensor: Gaussian blur σ 0.7 px, no speckle, a dim room (white ≈ 51/255).

Examples:
  omni-sim sensor --preset paper -o sensor/
  omni-sim sensor --preset paper --camera-offset 0.3,0,0.5 --facet-errors 0.02 --seed 1 -o bad-sensor/
  omni-sim scene --bench plane -o plane.json
  omni-sim scan --camera sensor/camera.json --scanner sensor/scanner.json --scene plane.json --angles 14:29:0.5 --frames frames/ -o scan.jsonl --truth truth.jsonl
  omni-sim boards --camera sensor/camera.json --board board.json --count 20 --seed 1 --out boards/
  omni-sim rig --camera sensor/camera.json --scanner sensor/scanner.json --board board.json --angles 14:28:1 --laser-off --out rig/";

/// The virtual sensor: writes sensor files, renders laser scans, checkerboard sets and the
/// transmitter-calibration rig, with ground truth.
#[derive(Parser, Debug)]
#[command(term_width = 0, version, about, after_help = AFTER_HELP)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Write camera.json and scanner.json of a sensor preset, optionally with build errors.
    Sensor(SensorArgs),
    /// Write a scene.json of the paper bench.
    Scene(SceneArgs),
    /// Render laser frames of a scene over mirror angles, with manifest and ground truth.
    Scan(ScanArgs),
    /// Render checkerboard images at random poses (receiver calibration), with true corners.
    Boards(BoardsArgs),
    /// Render the two-perpendicular-boards rig (transmitter calibration): pose image + laser frames.
    Rig(RigArgs),
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Preset {
    /// The paper's prototype with our lens and polygon dimensions.
    Paper,
}

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Example:\n  omni-sim sensor --preset paper --camera-offset 0.5,0,0 --encoder-offset 0.05 -o sensor/"
)]
struct SensorArgs {
    /// The sensor to start from: the paper's geometry (1024² camera, F/4 lens, 12-facet polygon).
    #[arg(long, value_enum, default_value = "paper")]
    preset: Preset,
    /// Output directory (created if missing).
    #[arg(short, long)]
    output: PathBuf,
    /// Image width and height (px); focal length and principal point scale with it.
    #[arg(long, default_value_t = 1024, allow_negative_numbers = true)]
    width: u32,
    /// Camera centre off the mirror focus, X,Y,Z (mm).
    #[arg(long, value_parser = parse_vec::<3>, allow_hyphen_values = true, value_name = "X,Y,Z")]
    camera_offset: Option<[f64; 3]>,
    /// Camera tilt about x then y, TX,TY (degrees).
    #[arg(long, value_parser = parse_vec::<2>, allow_hyphen_values = true, value_name = "TX,TY")]
    camera_tilt: Option<[f64; 2]>,
    /// Principal point shift from the image centre, DX,DY (px).
    #[arg(long, value_parser = parse_vec::<2>, allow_hyphen_values = true, value_name = "DX,DY")]
    principal_point_offset: Option<[f64; 2]>,
    /// Random per-facet tilt and pitch errors with this σ (degrees), radius errors σ = R·sin(σ).
    #[arg(long, default_value_t = 0.0, value_name = "SIGMA_DEG", allow_negative_numbers = true)]
    facet_errors: f64,
    /// Encoder zero offset (degrees).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_name = "DEG")]
    encoder_offset: f64,
    /// Seed of the random facet errors.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Bench {
    Plane,
    Cylinder,
    Sphere,
    ConePyramid,
}

#[derive(clap::Args, Debug)]
struct SceneArgs {
    /// Which paper-bench scene.
    #[arg(long, value_enum)]
    bench: Bench,
    /// Output file; `-` for stdout.
    #[arg(short, long, default_value = "-")]
    output: PathBuf,
}

/// Rendering options shared by the rendering subcommands.
#[derive(clap::Args, Debug)]
struct RenderArgs {
    /// Output bit depth of the PNG frames.
    #[arg(long, default_value_t = 8, value_parser = parse_bit_depth, allow_negative_numbers = true)]
    bit_depth: u8,
    /// Noise seed (same seed, same images).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
    /// Turn photon and read noise off.
    #[arg(long)]
    no_noise: bool,
    /// Laser power relative to the default (e.g. 3 for a saturated stripe, 0.3 for a weak one).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    laser_gain: f64,
    /// Ambient light relative to the default (a white surface ≈ 51/255 at 1 in laser frames; for
    /// checkerboard and rig pose images the room is lit: ≈ 178/255 at 1).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    ambient_gain: f64,
    /// Polygon turn during the exposure (degrees): motion blur of the stripe.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    motion_blur: f64,
    /// The idealised sensor instead of the realistic one: Gaussian PSF σ 0.7 px, no speckle, a
    /// dim room (white ≈ 51/255 in laser frames).
    #[arg(long)]
    ideal: bool,
    /// Lens F-number (default: camera.json's optics, else the paper preset's F/4).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    f_number: Option<f64>,
    /// Laser wavelength (nm; default 650).
    #[arg(long, value_name = "NM", allow_negative_numbers = true)]
    wavelength_nm: Option<f64>,
    /// Pixel pitch (µm; default 4.65 for a 1024-px image).
    #[arg(long, value_name = "UM", allow_negative_numbers = true)]
    pixel_pitch_um: Option<f64>,
    /// Defocus: diameter of the blur circle (px; default 1.5).
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    defocus_px: Option<f64>,
    /// Override the optical blur: σ of the PSF (px, 0.4–1.5 are typical; with a lens, the
    /// defocus is set to reach it and it cannot be below the diffraction limit).
    #[arg(long, value_name = "SIGMA_PX", allow_negative_numbers = true)]
    blur_px: Option<f64>,
    /// Image the laser incoherently: no speckle (the lens's blur stays).
    #[arg(long)]
    no_speckle: bool,
    /// Independent speckle patterns (2: a depolarising matte surface; 1: a polarisation-keeping one).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    speckle_patterns: Option<u32>,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    threads: usize,
}

impl RenderArgs {
    /// Options for laser frames, with the camera's optics where camera.json has them.
    fn options(&self, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        let base = if self.ideal { RenderOptions::ideal() } else { RenderOptions::default() };
        self.options_from(base, camera_optics)
    }

    /// Options for lit board images (no laser): `--ideal` keeps the ideal blur.
    fn lit_options(&self, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        let base = RenderOptions::calibration();
        let base = if self.ideal { RenderOptions { imaging: RenderOptions::ideal().imaging, ..base } } else { base };
        self.options_from(base, camera_optics)
    }

    /// Options on top of `d`.
    fn options_from(&self, d: RenderOptions, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        let imaging = self.imaging(d.imaging, camera_optics)?;
        let opts = RenderOptions {
            bit_depth: self.bit_depth,
            seed: self.seed,
            noise: !self.no_noise,
            laser_strength: d.laser_strength * self.laser_gain,
            ambient_e: d.ambient_e * self.ambient_gain,
            motion_blur_deg: self.motion_blur,
            imaging,
            ..d
        };
        opts.validate().map_err(|e| CliError::usage(format!("rendering options: {e}")))?;
        if self.threads > 0 {
            // Only the first call can set the global pool; later calls keep it.
            let _ = rayon::ThreadPoolBuilder::new().num_threads(self.threads).build_global();
        }
        Ok(opts)
    }
}

#[derive(clap::Args, Debug)]
#[command(after_help = "Frames are named frame_NNNNNN.png (and ambient_NNNNNN.png with --laser-off) in --frames.\n\
The manifest is the omniscan stream (header, one frame record per frame, status) that omni-ridge reads.\n\
The ground truth (--truth) holds per frame the true stripe points [x, y, z, u, v, laser].")]
struct ScanArgs {
    /// camera.json (from `omni-sim sensor`): the camera model, its image size and optics.
    #[arg(long)]
    camera: PathBuf,
    /// scanner.json (from `omni-sim sensor`): the polygon mirror and the lasers.
    #[arg(long)]
    scanner: PathBuf,
    /// scene.json (see `omni-sim scene`).
    #[arg(long)]
    scene: PathBuf,
    /// Mirror angles within the facet (degrees): start:stop:step (stop excluded) or a list a,b,c.
    #[arg(long, default_value = "0:30:0.5", allow_hyphen_values = true)]
    angles: String,
    /// Facet facing laser 0.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    facet: u32,
    /// Lasers switched on, e.g. 0,1.
    #[arg(long, default_value = "0,1", value_delimiter = ',', allow_hyphen_values = true)]
    lasers: Vec<u32>,
    /// Directory for the PNG frames (created if missing).
    #[arg(long)]
    frames: PathBuf,
    /// Also render a laser-off (ambient) frame for every frame.
    #[arg(long)]
    laser_off: bool,
    /// Manifest stream; `-` for stdout.
    #[arg(short, long, default_value = "-")]
    output: PathBuf,
    /// Ground-truth file (JSON Lines).
    #[arg(long)]
    truth: Option<PathBuf>,
    #[command(flatten)]
    render: RenderArgs,
}

#[derive(clap::Args, Debug)]
#[command(after_help = "Writes DIR/board_NNN.png and DIR/boards_truth.json (board, poses board→world, true corner\n\
pixels row-major, null where a corner is not visible).")]
struct BoardsArgs {
    /// camera.json (from `omni-sim sensor`): the camera model, its image size and optics.
    #[arg(long)]
    camera: PathBuf,
    /// board.json (inner corners, square size, margin).
    #[arg(long)]
    board: PathBuf,
    /// Number of images.
    #[arg(long, default_value_t = 20, allow_negative_numbers = true)]
    count: usize,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    render: RenderArgs,
}

const RIG_AFTER_HELP: &str = "\
Writes into DIR:
  pose.png            ambient image of the rig, lasers off, room lit (for --pose-image)
  frame_NNNNNN.png    laser frames (and ambient_NNNNNN.png, lasers off, with --laser-off)
  scan.jsonl          the manifest stream that omni-ridge reads
  rig.json            boards \"left\" and \"right\" (omniscan.rig, omni-calib-plane --rig)
  board_poses.json    their TRUE board→world poses (omniscan.board_poses, for --board-poses)
  board_corners.json  their TRUE corner pixels in pose.png (omniscan.board_corners)
  scene.json          the rig as an omniscan.scene (omni-trigger emulate --scene DIR/scene.json)
  rig_truth.json      the simulator's record (omniscan.sim-rig; corner pixels null if hidden)
  truth.jsonl         the true stripe points of every laser frame
The laser frames keep the room's dim ambient light (white squares ≈ 51/255): give --laser-off
so that omni-ridge subtracts the ambient frame instead of finding the squares' edges.

Example (light-plane calibration on the true camera and board poses):
  omni-sim rig --camera sensor/camera.json --scanner sensor/scanner.json --board board.json --angles 14:28:1 --laser-off --out rig/
  omni-ridge --camera sensor/camera.json rig/scan.jsonl -o stripes.jsonl
  omni-calib-plane fit --camera sensor/camera.json --rig rig/rig.json --board-poses rig/board_poses.json --stripes stripes.jsonl -o scanner.json";

#[derive(clap::Args, Debug)]
#[command(after_help = RIG_AFTER_HELP)]
struct RigArgs {
    /// camera.json (from `omni-sim sensor`): the camera model, its image size and optics.
    #[arg(long)]
    camera: PathBuf,
    /// scanner.json (from `omni-sim sensor`): the polygon mirror and the lasers.
    #[arg(long)]
    scanner: PathBuf,
    /// board.json of the two (identical) boards.
    #[arg(long)]
    board: PathBuf,
    /// Mirror angles (degrees): start:stop:step (stop excluded) or a list.
    #[arg(long, default_value = "14:28:1", allow_hyphen_values = true)]
    angles: String,
    /// Facet facing laser 0.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    facet: u32,
    /// Also render a laser-off (ambient) frame for every laser frame (`ambient_path` in the
    /// manifest), so that omni-ridge subtracts the checkerboard.
    #[arg(long)]
    laser_off: bool,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    render: RenderArgs,
}

impl RenderArgs {
    /// The lens: the ideal Gaussian (with `--ideal`) or the optics, from camera.json and flags.
    fn imaging(&self, d: Imaging, camera_optics: Option<Optics>) -> CliResult<Imaging> {
        let usage = |e: String| CliError::usage(format!("optics: {e}"));
        match d {
            Imaging::Gaussian { sigma_px } => {
                let lens_flags = [self.f_number, self.wavelength_nm, self.pixel_pitch_um, self.defocus_px];
                if lens_flags.iter().any(Option::is_some) || self.speckle_patterns.is_some() || self.no_speckle {
                    return Err(CliError::usage(
                        "--ideal has no lens: drop --f-number, --wavelength-nm, --pixel-pitch-um, --defocus-px, --speckle-patterns and --no-speckle",
                    ));
                }
                Ok(Imaging::Gaussian { sigma_px: self.blur_px.unwrap_or(sigma_px) })
            }
            Imaging::Lens { optics, speckle } => {
                let base = camera_optics.unwrap_or(optics);
                let mut o = Optics {
                    f_number: self.f_number.unwrap_or(base.f_number),
                    wavelength_nm: self.wavelength_nm.unwrap_or(base.wavelength_nm),
                    pixel_pitch_um: self.pixel_pitch_um.unwrap_or(base.pixel_pitch_um),
                    defocus_px: self.defocus_px.unwrap_or(base.defocus_px),
                    speckle_patterns: self.speckle_patterns.unwrap_or(base.speckle_patterns),
                };
                o.validate().map_err(usage)?;
                if let Some(b) = self.blur_px {
                    o = o.with_psf_sigma(b).map_err(|e| CliError::usage(format!("--blur-px: {e}")))?;
                }
                Ok(Imaging::Lens { optics: o, speckle: speckle && !self.no_speckle })
            }
        }
    }
}

fn parse_bit_depth(s: &str) -> Result<u8, String> {
    match s {
        "8" => Ok(8),
        "16" => Ok(16),
        _ => Err(format!("must be 8 or 16, got \"{s}\"")),
    }
}

fn parse_vec<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|_| format!("\"{}\" is not a number", x.trim())))
        .collect::<Result<_, _>>()?;
    let arr: [f64; N] =
        v.try_into().map_err(|v: Vec<f64>| format!("expected {N} comma-separated numbers, got {}", v.len()))?;
    if arr.iter().all(|x| x.is_finite()) { Ok(arr) } else { Err("numbers must be finite".into()) }
}

fn main() -> ExitCode {
    omni_cli::main("omni-sim", || match Args::parse().command {
        Command::Sensor(a) => sensor(a),
        Command::Scene(a) => scene(a),
        Command::Scan(a) => scan(a),
        Command::Boards(a) => boards(a),
        Command::Rig(a) => rig(a),
    })
}

fn create_dir(dir: &Path) -> CliResult {
    std::fs::create_dir_all(dir).map_err(|e| CliError::new(format!("{}: {e}", dir.display())))
}

fn sensor(a: SensorArgs) -> CliResult {
    let Preset::Paper = a.preset;
    if !(16..=8192).contains(&a.width) {
        return Err(CliError::usage(format!("--width must be in 16..=8192, got {}", a.width)));
    }
    let imp = Imperfections {
        camera_offset_mm: a.camera_offset.unwrap_or_default(),
        camera_tilt_deg: a.camera_tilt.unwrap_or_default(),
        principal_point_offset_px: a.principal_point_offset.unwrap_or_default(),
        facet_sigma_deg: a.facet_errors,
        encoder_offset_deg: a.encoder_offset,
        seed: a.seed,
    };
    let (cam, tx) = paper_preset(a.width, &imp).map_err(CliError::usage)?;
    create_dir(&a.output)?;
    // A smaller image keeps the pixel (and so its blur and speckle in pixels) with a shorter lens.
    let camera = CameraFile { optics: Some(Optics::paper()), ..CameraFile::new(CameraSpec::Hyperbolic(cam)) };
    write_doc(&a.output.join("camera.json"), &camera)?;
    write_doc(&a.output.join("scanner.json"), &ScannerFile::new(tx))?;
    Ok(())
}

fn scene(a: SceneArgs) -> CliResult {
    let object = match a.bench {
        Bench::Plane => BenchObject::Plane,
        Bench::Cylinder => BenchObject::Cylinder,
        Bench::Sphere => BenchObject::Sphere,
        Bench::ConePyramid => BenchObject::ConePyramid,
    };
    write_doc(&a.output, &paper_bench(object))?;
    Ok(())
}

/// Renders the sweep into `frames_dir` with a progress bar.
fn render_frames(
    sensor: &Sensor,
    scene: &Scene,
    sweep: &Sweep,
    frames_dir: &Path,
    opts: &RenderOptions,
) -> CliResult<Vec<RenderedFrame>> {
    let bar = omni_cli::progress(Some(sweep.angles_deg.len() as u64), "rendering");
    let out = render_sweep(sensor, scene, sweep, frames_dir, opts, &|| bar.inc(1));
    bar.finish_and_clear();
    Ok(out?)
}

/// The producer named in the manifests' headers.
const PRODUCER: &str = concat!("omni-sim ", env!("CARGO_PKG_VERSION"));

fn load_board(path: &Path) -> CliResult<BoardFile> {
    let board: BoardFile = omni_formats::read_doc(path)?;
    board.validate().map_err(|e| CliError::new(format!("{}: {e}", path.display())))?;
    Ok(board)
}

fn check_lasers(sensor: &Sensor, lasers: &[u32]) -> CliResult {
    match lasers.iter().find(|l| **l as usize >= sensor.transmitter.num_lasers()) {
        Some(l) => Err(CliError::usage(format!(
            "--lasers: laser {l} does not exist (the scanner has {})",
            sensor.transmitter.num_lasers()
        ))),
        None => Ok(()),
    }
}

/// The facet must be on the polygon (not taken modulo its count) and every angle within (or
/// near) one facet's range.
fn check_facet_and_angles(sensor: &Sensor, facet: u32, angles: &[f64]) -> CliResult {
    let n = sensor.transmitter.num_facets();
    if facet >= n {
        return Err(CliError::usage(format!(
            "--facet: facet {facet} is not on the polygon ({n} facets, 0 to {})",
            n - 1
        )));
    }
    if let Some(a) = angles.iter().find(|a| sensor.transmitter.check_frame(a.to_radians(), facet).is_err()) {
        let span = sensor.transmitter.facet_angle().to_degrees();
        return Err(CliError::usage(format!("--angles: {a}° is far outside the facet's range [0, {span}°)")));
    }
    Ok(())
}

fn scan(a: ScanArgs) -> CliResult {
    let (sensor, optics) = Sensor::load_with_optics(&a.camera, &a.scanner)?;
    let opts = a.render.options(optics)?;
    let angles = parse_angles(&a.angles).map_err(|e| CliError::usage(format!("--angles: {e}")))?;
    check_facet_and_angles(&sensor, a.facet, &angles)?;
    check_lasers(&sensor, &a.lasers)?;
    let scene = Scene::load(&a.scene)?;
    check_boards_visible(&sensor, &scene).map_err(|e| CliError::new(format!("{}: {e}", a.scene.display())))?;
    create_dir(&a.frames)?;
    let sweep = Sweep { angles_deg: &angles, facet: a.facet, lasers: &a.lasers, laser_off: a.laser_off };
    let frames = render_frames(&sensor, &scene, &sweep, &a.frames, &opts)?;
    if let Some(t) = &a.truth {
        write_truth(t, &a.scene.display().to_string(), &frames)?;
    }
    Ok(write_manifest(&a.output, PRODUCER, &a.frames, &a.camera, &a.scanner, &frames)?)
}

fn boards(a: BoardsArgs) -> CliResult {
    let (file, camera) = CameraFile::load(&a.camera)?;
    let opts = a.render.lit_options(file.optics)?;
    let board = load_board(&a.board)?;
    if !(1..=10_000).contains(&a.count) {
        return Err(CliError::usage(format!("--count must be in 1..=10000, got {}", a.count)));
    }
    // The transmitter plays no part in board images; the paper's stands in.
    let sensor = Sensor { camera, transmitter: Sensor::paper().transmitter };
    let poses = random_board_poses(&sensor, &board, a.count, opts.seed).map_err(CliError::new)?;
    create_dir(&a.out)?;
    let bar = omni_cli::progress(Some(poses.len() as u64), "boards");
    let images = poses
        .par_iter()
        .enumerate()
        .map(|(i, pose)| -> CliResult<serde_json::Value> {
            let o = RenderOptions { seed: opts.seed ^ (0xB0A2D00 + i as u64), ..opts.clone() };
            let (image, corners) = render_board_image(&sensor, pose, &board, &o);
            let name = format!("board_{i:03}.png");
            image.to_png(&a.out.join(&name))?;
            bar.inc(1);
            Ok(serde_json::json!({"path": name, "pose": BoardPose::from_isometry(pose), "corners": corners}))
        })
        .collect::<CliResult<Vec<_>>>()?;
    bar.finish_and_clear();
    let doc = serde_json::json!({"format": "omniscan.sim-boards", "version": 1, "board": board,
        "camera": a.camera.display().to_string(), "images": images});
    write_doc(&a.out.join("boards_truth.json"), &doc)?;
    Ok(())
}

fn rig(a: RigArgs) -> CliResult {
    let (sensor, optics) = Sensor::load_with_optics(&a.camera, &a.scanner)?;
    let opts = a.render.options(optics)?;
    let angles = parse_angles(&a.angles).map_err(|e| CliError::usage(format!("--angles: {e}")))?;
    check_facet_and_angles(&sensor, a.facet, &angles)?;
    let board = load_board(&a.board)?;
    let rig = Rig::standard(&board);
    let scene_file = rig.scene();
    let scene = Scene::from_file(scene_file.clone()).map_err(CliError::new)?;
    check_boards_visible(&sensor, &scene).map_err(|e| CliError::new(format!("rig: {e}")))?;
    create_dir(&a.out)?;
    let lit = a.render.lit_options(optics)?;
    let (pose_image, corners) = render_rig_pose_image(&sensor, &rig, &lit);
    pose_image.to_png(&a.out.join("pose.png"))?;
    let sweep = Sweep { angles_deg: &angles, facet: a.facet, lasers: &[0, 1], laser_off: a.laser_off };
    let frames = render_frames(&sensor, &scene, &sweep, &a.out, &opts)?;
    write_truth(&a.out.join("truth.jsonl"), "rig", &frames)?;
    write_doc(&a.out.join("scene.json"), &scene_file)?;
    write_doc(&a.out.join("rig.json"), &rig.rig_file())?;
    write_doc(&a.out.join("board_poses.json"), &rig.board_poses_file())?;
    write_doc(&a.out.join("board_corners.json"), &rig.board_corners_file(&corners))?;
    let truth = serde_json::json!({
        "format": "omniscan.sim-rig", "version": 1, "board": board, "board_names": Rig::BOARD_NAMES,
        "pose_image": "pose.png",
        "poses": rig.poses.iter().map(BoardPose::from_isometry).collect::<Vec<_>>(),
        "corners": corners,
    });
    write_doc(&a.out.join("rig_truth.json"), &truth)?;
    // The manifest last: its presence means the rig directory is complete.
    Ok(write_manifest(&a.out.join("scan.jsonl"), PRODUCER, &a.out, &a.camera, &a.scanner, &frames)?)
}
