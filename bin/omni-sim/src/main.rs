//! omni-sim: the virtual omnidirectional line-laser sensor (see the `omni_simulator` crate).

use clap::{Parser, Subcommand, ValueEnum};
use omni_cli::{CliError, CliResult};
use omni_formats::{BoardFile, CameraFile, CameraSpec, ScannerFile, write_doc};
use omni_simulator::{
    BayerPattern, BenchObject, Bloom, BloomAxis, BoardPose, CameraColour, Colour, ColourOutput, FrameFormat, Halo,
    Imaging, Imperfections, Optics, RenderOptions, RenderedFrame, Rig, Scene, Sensor, SheetProfile, Sweep,
    check_boards_visible, paper_bench, paper_preset, parse_angles, random_board_poses, render_board_image,
    render_rig_pose_image, render_sweep_as, write_manifest, write_truth,
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
    /// Write the lens focused on the plane this far ahead of it (mm; camera.json's
    /// optics.focus_mm) instead of the preset's one 1.5 px blur circle: each part of the frame is
    /// then blurred as the mirror makes it (see `scan --focus-mm`).
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    focus_mm: Option<f64>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Bench {
    Plane,
    Cylinder,
    Sphere,
    ConePyramid,
}

#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  omni-sim scene --bench sphere -o sphere.json")]
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
    /// Output bit depth of the frames.
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
    /// Laser wavelength (nm; default: camera.json's optics, else 650).
    #[arg(long, value_name = "NM", allow_negative_numbers = true)]
    wavelength_nm: Option<f64>,
    /// Pixel pitch (µm; default: camera.json's optics, else 4.65; `sensor` writes 4.65 at every
    /// --width, with a focal length that keeps the field of view).
    #[arg(long, value_name = "UM", allow_negative_numbers = true)]
    pixel_pitch_um: Option<f64>,
    /// Defocus: diameter of the blur circle (px; default: camera.json's optics, else 1.5).
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    defocus_px: Option<f64>,
    /// Focus the lens on the plane this far ahead of it (mm, along its axis; default:
    /// camera.json's optics) instead of one --defocus-px for the whole image: the mirror's
    /// virtual image of the scene is curved, so the frame is sharp along one ring and blurs on
    /// either side of it, more for nearer surfaces. The paper's sensor is sharpest about 243 px
    /// from the centre when focused at 91 mm and 320 px at 100 mm. Needs a hyperbolic camera;
    /// --defocus-px or --blur-px instead sets one blur for the frame, whatever camera.json says.
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    focus_mm: Option<f64>,
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
    /// Worker threads (0: one per core; at most 1024).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = omni_cli::parse_threads)]
    threads: usize,
    #[command(flatten)]
    stripe: StripeArgs,
}

/// Real-looking stripes: the sheet's profile and width, saturation, colour and the frames' files.
#[derive(clap::Args, Debug)]
#[command(next_help_heading = "Real-looking stripes (laser frames: scan, rig)")]
struct StripeArgs {
    /// The laser sheet's profile across its plane: `gaussian` (the default), or `real`: the
    /// cross-section measured on real line-laser photographs, a Gaussian core with a one-sided
    /// exponential tail (17 % of the light, 4 core σ long) on the plane normal's side. The
    /// profile's peak lies on the light plane, where the ground truth is.
    #[arg(long, value_enum, default_value = "gaussian")]
    profile: ProfileKind,
    /// A tailed profile of your own: tail weight (0–0.9), tail length (in core σ) and side
    /// (1: towards the light plane's normal, -1: away); implies the tailed shape.
    #[arg(long, value_parser = parse_vec::<3>, allow_hyphen_values = true, value_name = "W,LEN,SIDE")]
    tail: Option<[f64; 3]>,
    /// The sheet's FWHM across its plane (mm; default 0.5).
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    beam_fwhm_mm: Option<f64>,
    /// Make each laser's stripe this wide (FWHM in px, the optics' blur and the pixel included)
    /// at the middle of its stripe, frame by frame, by setting the sheet's width (2–20 px are
    /// what real sensors show). With a lens focused at a distance (--focus-mm), a stripe whose
    /// middle the lens alone blurs wider keeps the sheet of --beam-fwhm-mm.
    #[arg(long, value_name = "PX", allow_negative_numbers = true)]
    stripe_fwhm_px: Option<f64>,
    /// Blooming: charge above the full well spills along the `columns` or `rows` into the next
    /// pixels with room (half each way), so a saturated stripe grows a flat plateau.
    #[arg(long, value_enum, value_name = "AXIS")]
    bloom: Option<BloomKind>,
    /// The share of the excess charge that spills (the anti-blooming drain takes the rest).
    #[arg(long, default_value_t = 1.0, value_name = "SHARE", allow_negative_numbers = true)]
    bloom_spill: f64,
    /// Veiling glare: this share of all light spread into a Gaussian glow of σ px.
    #[arg(long, value_parser = parse_vec::<2>, allow_hyphen_values = true, value_name = "SHARE,SIGMA_PX")]
    halo: Option<[f64; 2]>,
    /// A colour camera (camera.json's `colour` section, else a default one): `rgb` frames
    /// (demosaiced, white-balanced, through the colour matrix; colour PNG or JPEG), or `raw`: the
    /// Bayer mosaic as a grey frame (needs a mosaic, --bayer or camera.json's `bayer`).
    #[arg(long, value_enum, value_name = "OUTPUT")]
    colour: Option<ColourKind>,
    /// The colour filter mosaic, row 0 then row 1: rggb, bggr, grbg or gbrg (`rggb`: row 0 R G,
    /// row 1 G B).
    #[arg(long, value_parser = BayerPattern::parse, value_name = "ORDER")]
    bayer: Option<BayerPattern>,
    /// Raw R,G,B response to the laser (monochrome pixel = 1; default: the filter curves at the
    /// laser's wavelength, at 650 nm 0.81, 0.08, 0.11).
    #[arg(long, value_parser = parse_vec::<3>, value_name = "R,G,B")]
    laser_rgb: Option<[f64; 3]>,
    /// Raw R,G,B response to the room light (default 0.47,0.81,0.46: a reddish room, white paper
    /// about 1 : 0.8 : 0.7 in the output).
    #[arg(long, value_parser = parse_vec::<3>, value_name = "R,G,B")]
    ambient_rgb: Option<[f64; 3]>,
    /// Output gamma (1 = linear; 2.2 as cameras encode for display).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    gamma: f64,
    /// File format of the laser (and laser-off) frames: png, pgm (grey frames and raw mosaics
    /// only) or jpeg (8 bits; colour with 4:2:0 chroma, as cameras write it).
    #[arg(long, value_enum, default_value = "png")]
    format: FormatKind,
    /// JPEG quality (1–100).
    #[arg(long, default_value_t = 90, value_name = "Q", allow_negative_numbers = true)]
    jpeg_quality: i64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ProfileKind {
    Gaussian,
    Real,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum BloomKind {
    Columns,
    Rows,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ColourKind {
    Rgb,
    Raw,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum FormatKind {
    Png,
    Pgm,
    Jpeg,
}

impl StripeArgs {
    /// Whether any option for laser frames only is given.
    fn any(&self) -> bool {
        !matches!(self.profile, ProfileKind::Gaussian)
            || self.tail.is_some()
            || self.beam_fwhm_mm.is_some()
            || self.stripe_fwhm_px.is_some()
            || self.bloom.is_some()
            || self.halo.is_some()
            || self.colour.is_some()
            || self.bayer.is_some()
            || self.laser_rgb.is_some()
            || self.ambient_rgb.is_some()
            || self.gamma != 1.0
            || !matches!(self.format, FormatKind::Png)
    }

    /// The options on top of `opts`, with camera.json's colour section and the laser's wavelength.
    fn apply(
        &self,
        opts: RenderOptions,
        colour: Option<&CameraColour>,
        wavelength_nm: f64,
    ) -> CliResult<RenderOptions> {
        let profile = match (self.tail, self.profile) {
            (Some([w, len, side]), _) => {
                if side != 1.0 && side != -1.0 {
                    return Err(CliError::usage(format!("--tail: the side must be 1 or -1, got {side}")));
                }
                SheetProfile::Tailed { tail_weight: w, tail_length: len, tail_side: side as i8 }
            }
            (None, ProfileKind::Real) => SheetProfile::real(),
            (None, ProfileKind::Gaussian) => SheetProfile::Gaussian,
        };
        let bloom = self.bloom.map(|axis| Bloom {
            axis: match axis {
                BloomKind::Columns => BloomAxis::Columns,
                BloomKind::Rows => BloomAxis::Rows,
            },
            spill: self.bloom_spill,
        });
        let colour_flags = self.bayer.is_some() || self.laser_rgb.is_some() || self.ambient_rgb.is_some();
        if self.colour.is_none() && colour_flags {
            return Err(CliError::usage("--bayer, --laser-rgb and --ambient-rgb need --colour rgb or --colour raw"));
        }
        let colour = match self.colour {
            None => None,
            Some(kind) => {
                let mut camera = colour.cloned().unwrap_or_default();
                camera.bayer = self.bayer.or(camera.bayer);
                camera.laser_rgb = self.laser_rgb.or(camera.laser_rgb);
                camera.ambient_rgb = self.ambient_rgb.unwrap_or(camera.ambient_rgb);
                let output = match kind {
                    ColourKind::Rgb => ColourOutput::Rgb,
                    ColourKind::Raw => ColourOutput::Raw,
                };
                if output == ColourOutput::Raw && camera.bayer.is_none() {
                    return Err(CliError::usage(
                        "--colour raw writes the Bayer mosaic: give its order with --bayer (or camera.json's colour.bayer)",
                    ));
                }
                Some(Colour::new(&camera, wavelength_nm, output))
            }
        };
        if matches!(self.format, FormatKind::Pgm) && matches!(self.colour, Some(ColourKind::Rgb)) {
            return Err(CliError::usage("--format pgm holds grey frames: use png or jpeg for --colour rgb"));
        }
        Ok(RenderOptions {
            profile,
            beam_fwhm_mm: self.beam_fwhm_mm.unwrap_or(opts.beam_fwhm_mm),
            stripe_fwhm_px: self.stripe_fwhm_px,
            bloom,
            halo: self.halo.map(|[fraction, sigma_px]| Halo { fraction, sigma_px }),
            colour,
            gamma: self.gamma,
            ..opts
        })
    }

    /// The frames' file format.
    fn frame_format(&self) -> CliResult<FrameFormat> {
        Ok(match self.format {
            FormatKind::Png => FrameFormat::Png,
            FormatKind::Pgm => FrameFormat::Pgm,
            FormatKind::Jpeg => {
                let quality =
                    u8::try_from(self.jpeg_quality).ok().filter(|q| (1..=100).contains(q)).ok_or_else(|| {
                        CliError::usage(format!("--jpeg-quality must be within 1–100, got {}", self.jpeg_quality))
                    })?;
                FrameFormat::Jpeg { quality }
            }
        })
    }
}

impl RenderArgs {
    /// Options for laser frames, with the camera's optics and colour where camera.json has them.
    fn options(&self, camera_optics: Option<Optics>, camera_colour: Option<&CameraColour>) -> CliResult<RenderOptions> {
        let base = if self.ideal { RenderOptions::ideal() } else { RenderOptions::default() };
        let opts = self.options_from(base, camera_optics)?;
        let wavelength = match &opts.imaging {
            Imaging::Lens { optics, .. } => optics.wavelength_nm,
            Imaging::Gaussian { .. } => camera_optics.map_or(650.0, |o| o.wavelength_nm),
        };
        let opts = self.stripe.apply(opts, camera_colour, wavelength)?;
        opts.validate().map_err(|e| CliError::usage(format!("rendering options: {e}")))?;
        Ok(opts)
    }

    /// Options for lit board images (no laser): `--ideal` keeps the ideal blur.
    fn lit_options(&self, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        if self.stripe.any() {
            return Err(CliError::usage(
                "the stripe options (--profile, --tail, --beam-fwhm-mm, --stripe-fwhm-px, --bloom, --halo, --colour, --bayer, \
                 --laser-rgb, --ambient-rgb, --gamma, --format) are for laser frames: scan and rig",
            ));
        }
        let laser_only = self.laser_gain != 1.0 || self.motion_blur != 0.0;
        if laser_only || self.no_speckle || self.speckle_patterns.is_some() {
            return Err(CliError::usage(
                "--laser-gain, --motion-blur, --no-speckle and --speckle-patterns act on the laser's light: \
                 board images are lit by the room alone",
            ));
        }
        let base = RenderOptions::calibration();
        let base = if self.ideal { RenderOptions { imaging: RenderOptions::ideal().imaging, ..base } } else { base };
        self.options_from(base, camera_optics)
    }

    /// Options for the rig's lit pose image: grey PNG whatever the stripe options say.
    fn lit_options_for_rig(&self, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        let base = RenderOptions::calibration();
        let base = if self.ideal { RenderOptions { imaging: RenderOptions::ideal().imaging, ..base } } else { base };
        self.options_from(base, camera_optics)
    }

    /// Checks that the camera in `camera_path` can render `opts` ([`RenderOptions::check_sensor`]):
    /// a usage error when the focus came from --focus-mm, else a data error naming the file.
    fn check_sensor(&self, opts: &RenderOptions, sensor: &Sensor, camera_path: &Path) -> CliResult {
        opts.check_sensor(sensor).map_err(|e| match self.focus_mm {
            Some(_) => CliError::usage(format!("--focus-mm: {e}")),
            None => CliError::new(format!("{}: {e}", camera_path.display())),
        })
    }

    /// Options on top of `d`.
    fn options_from(&self, d: RenderOptions, camera_optics: Option<Optics>) -> CliResult<RenderOptions> {
        for (option, gain) in [("--laser-gain", self.laser_gain), ("--ambient-gain", self.ambient_gain)] {
            if !(gain.is_finite() && gain >= 0.0) {
                return Err(CliError::usage(format!("{option} must be a non-negative number, got {gain}")));
            }
        }
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
#[command(after_help = SCAN_AFTER_HELP)]
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
    /// Directory for the frames (created if missing).
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
pixels row-major, null where a corner is not visible).\n\n\
Example:\n  omni-sim boards --camera sensor/camera.json --board board.json --count 20 --seed 1 --out boards/")]
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

const SCAN_AFTER_HELP: &str = "\
Frames are named frame_NNNNNN.png (.pgm, .jpg with --format; and ambient_NNNNNN.* with --laser-off)
in --frames. The manifest is the omniscan stream (header, one frame record per frame, status) that
omni-ridge reads. The ground truth (--truth) holds per frame the true stripe points
[x, y, z, u, v, laser]: where the light plane meets the surface, i.e. the peak of the sheet's
profile (for --profile real not its centroid: the tail does not move it). With --profile, --tail or
--stripe-fwhm-px a frame's record also names the profile and each laser's sheet FWHM (mm).

Real-looking stripes (see docs/DECISIONS.md, \"Real stripe cross-sections\"):
  # a lopsided real-profile stripe 12 px wide, on the idealised sensor, noiseless, with truth
  omni-sim scan --camera sensor/camera.json --scanner sensor/scanner.json --scene plane.json \\
    --ideal --no-noise --profile real --stripe-fwhm-px 12 --frames f/ -o scan.jsonl --truth truth.jsonl
  # a close, saturated stripe: a flat white plateau that blooms down the columns, with a glow
  ... --profile real --stripe-fwhm-px 10 --laser-gain 60 --bloom columns --halo 0.02,10
  # a colour camera: RGB frames through an RGGB mosaic, saved as JPEG with 4:2:0 chroma
  ... --colour rgb --bayer rggb --gamma 2.2 --format jpeg --jpeg-quality 90
  # the raw Bayer mosaic of a BGGR sensor as a 16-bit grey PGM
  ... --colour raw --bayer bggr --bit-depth 16 --format pgm";

const RIG_AFTER_HELP: &str = "\
Writes into DIR:
  pose.png            ambient image of the rig, lasers off, the boards lit (for --pose-image)
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
                let lens_flags =
                    [self.f_number, self.wavelength_nm, self.pixel_pitch_um, self.defocus_px, self.focus_mm];
                if lens_flags.iter().any(Option::is_some) || self.speckle_patterns.is_some() || self.no_speckle {
                    return Err(CliError::usage(
                        "--ideal has no lens: drop --f-number, --wavelength-nm, --pixel-pitch-um, --defocus-px, --focus-mm, --speckle-patterns and --no-speckle",
                    ));
                }
                Ok(Imaging::Gaussian { sigma_px: self.blur_px.unwrap_or(sigma_px) })
            }
            Imaging::Lens { optics, speckle } => {
                let base = camera_optics.unwrap_or(optics);
                // The flags override camera.json: one blur for the frame (--defocus-px, --blur-px)
                // replaces the file's focus distance, and --focus-mm the file's one blur.
                let one_blur = self.defocus_px.is_some() || self.blur_px.is_some();
                if self.focus_mm.is_some() && one_blur {
                    return Err(CliError::usage(
                        "--focus-mm blurs each part of the frame as the mirror makes it; --defocus-px and --blur-px \
                         set one blur for the whole frame: give one of them",
                    ));
                }
                let focus_mm = if one_blur { None } else { self.focus_mm.or(base.focus_mm) };
                let defocus_px = match (self.defocus_px, focus_mm) {
                    (Some(d), _) => d,
                    (None, Some(_)) => 0.0,
                    (None, None) => base.defocus_px,
                };
                let mut o = Optics {
                    f_number: self.f_number.unwrap_or(base.f_number),
                    wavelength_nm: self.wavelength_nm.unwrap_or(base.wavelength_nm),
                    pixel_pitch_um: self.pixel_pitch_um.unwrap_or(base.pixel_pitch_um),
                    defocus_px,
                    focus_mm,
                    speckle_patterns: self.speckle_patterns.unwrap_or(base.speckle_patterns),
                };
                o.validate().map_err(usage)?;
                if let Some(b) = self.blur_px {
                    o = o.with_psf_sigma(b).map_err(|e| CliError::usage(format!("--blur-px {b}: {e}")))?;
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
    omni_cli::main("omni-sim", || match omni_cli::parse_args::<Args>()?.command {
        Command::Sensor(a) => sensor(a),
        Command::Scene(a) => scene(a),
        Command::Scan(a) => scan(a),
        Command::Boards(a) => boards(a),
        Command::Rig(a) => rig(a),
    })
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
    // A smaller image keeps the pixel (and so its blur and speckle in pixels) with a shorter lens.
    let optics = match a.focus_mm {
        Some(focus) => Optics::paper().focused_at(focus),
        None => Optics::paper(),
    };
    optics.validate().map_err(|e| CliError::usage(format!("--focus-mm: {e}")))?;
    let lens = RenderOptions::default().with_optics(optics);
    let check = Sensor::from_params(cam.clone(), tx.clone()).map_err(CliError::usage)?;
    lens.check_sensor(&check).map_err(|e| CliError::usage(format!("--focus-mm: {e}")))?;
    omni_cli::create_output_dir("--output", &a.output)?;
    let camera = CameraFile { optics: Some(optics), ..CameraFile::new(CameraSpec::Hyperbolic(cam)) };
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

/// Renders the sweep into `frames_dir` as `format` with a progress bar.
fn render_frames(
    sensor: &Sensor,
    scene: &Scene,
    sweep: &Sweep,
    frames_dir: &Path,
    opts: &RenderOptions,
    format: FrameFormat,
) -> CliResult<Vec<RenderedFrame>> {
    let bar = omni_cli::progress(Some(sweep.angles_deg.len() as u64), "rendering");
    let out = render_sweep_as(sensor, scene, sweep, frames_dir, opts, format, &|| bar.inc(1));
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
    for a in angles {
        sensor
            .transmitter
            .check_alpha(a.to_radians())
            .map_err(|e| CliError::usage(format!("--angles: {a}° is {e}")))?;
    }
    Ok(())
}

/// Whether two output paths name one file (`-` both stdout, or one path written two ways).
fn same_output(a: &std::path::Path, b: &std::path::Path) -> bool {
    let resolved = |p: &std::path::Path| match (p.parent(), p.file_name()) {
        (Some(dir), Some(name)) => {
            let dir = if dir.as_os_str().is_empty() { std::path::Path::new(".") } else { dir };
            dir.canonicalize().ok().map(|d| d.join(name))
        }
        _ => None,
    };
    a == b || resolved(a).is_some_and(|ra| resolved(b).is_some_and(|rb| ra == rb))
}

fn scan(a: ScanArgs) -> CliResult {
    let (sensor, optics) = Sensor::load_with_optics(&a.camera, &a.scanner)?;
    let colour = CameraFile::load(&a.camera)?.0.colour;
    let opts = a.render.options(optics, colour.as_ref())?;
    a.render.check_sensor(&opts, &sensor, &a.camera)?;
    let format = a.render.stripe.frame_format()?;
    let angles = parse_angles(&a.angles).map_err(|e| CliError::usage(format!("--angles: {e}")))?;
    check_facet_and_angles(&sensor, a.facet, &angles)?;
    check_lasers(&sensor, &a.lasers)?;
    let scene = Scene::load(&a.scene)?;
    check_boards_visible(&sensor, &scene).map_err(|e| CliError::new(format!("{}: {e}", a.scene.display())))?;
    if a.truth.as_ref().is_some_and(|t| same_output(t, &a.output)) {
        return Err(CliError::usage(format!(
            "--truth and -o both name {}: the manifest and the ground truth need a file each",
            a.output.display()
        )));
    }
    for output in std::iter::once(&a.output).chain(&a.truth) {
        omni_formats::io::check_output_dir(output)?;
    }
    omni_cli::create_output_dir("--frames", &a.frames)?;
    let sweep = Sweep { angles_deg: &angles, facet: a.facet, lasers: &a.lasers, laser_off: a.laser_off };
    let frames = render_frames(&sensor, &scene, &sweep, &a.frames, &opts, format)?;
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
    a.render.check_sensor(&opts, &sensor, &a.camera)?;
    let poses = random_board_poses(&sensor, &board, a.count, opts.seed).map_err(CliError::new)?;
    omni_cli::create_output_dir("--out", &a.out)?;
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
    let colour = CameraFile::load(&a.camera)?.0.colour;
    let opts = a.render.options(optics, colour.as_ref())?;
    a.render.check_sensor(&opts, &sensor, &a.camera)?;
    let format = a.render.stripe.frame_format()?;
    let angles = parse_angles(&a.angles).map_err(|e| CliError::usage(format!("--angles: {e}")))?;
    check_facet_and_angles(&sensor, a.facet, &angles)?;
    let board = load_board(&a.board)?;
    let rig = Rig::standard(&board);
    let scene_file = rig.scene();
    let scene = Scene::from_file(scene_file.clone()).map_err(CliError::new)?;
    check_boards_visible(&sensor, &scene).map_err(|e| CliError::new(format!("rig: {e}")))?;
    omni_cli::create_output_dir("--out", &a.out)?;
    let lit = RenderArgs::lit_options_for_rig(&a.render, optics)?;
    let (pose_image, corners) = render_rig_pose_image(&sensor, &rig, &lit);
    pose_image.to_png(&a.out.join("pose.png"))?;
    let sweep = Sweep { angles_deg: &angles, facet: a.facet, lasers: &[0, 1], laser_off: a.laser_off };
    let frames = render_frames(&sensor, &scene, &sweep, &a.out, &opts, format)?;
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
