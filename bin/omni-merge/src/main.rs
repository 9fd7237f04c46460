//! omni-merge: point streams and PLY clouds → one cleaned PLY cloud.

use clap::Parser;
use omni_cli::CliError;
use omni_cloud::export::CloudOutputArgs;
use omni_cloud::filter::CropBox;
use omni_cloud::merge::{MergeOptions, Merger};
use omni_cloud::motion::Trajectory;
use omni_cloud::normals::Viewpoints;
use omni_formats::rosbag::BagMessage;
use omni_formats::stream::{Record, StreamReader};
use std::path::{Path, PathBuf};

#[derive(Parser, Debug)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    version,
    about = "Merge point streams and PLY clouds into one cloud (PLY, PCD, LAS, ROS 2 bag): poses, crop, voxel grid, outlier removal.",
    long_about = "Reads triangulated point streams (JSON Lines from omni-triangulate; `-` = stdin) and PLY \
clouds (by the .ply extension), optionally moves each frame by the sensor pose interpolated from an \
odometry file at the frame's timestamp_us (slerp + lerp), then crops, voxel-downsamples and removes \
outliers, in that order, and writes one cloud: PLY, PCD or LAS by the output's extension (or \
--format), optionally with normals facing the point each stream's rays start from (its header's \
viewpoint_mm; with --poses: where it was when each point's frame was taken; a PLY input's: the origin), and/or a ROS 2 bag (--rosbag) with the merged \
cloud as one sensor_msgs/msg/PointCloud2 message in frame `map`, stamped with the latest frame \
timestamp (0 where no frame has one). Scalar fields keep their PLY types (uchar colours stay uchar).\n\n\
Outlier removal matches Open3D: --statistical K,STD_RATIO is remove_statistical_outlier(nb_neighbors=K, \
std_ratio): mean distance to the K nearest points counting the point itself, kept if below \
mean + STD_RATIO·std over the cloud. --radius R,MIN_POINTS is remove_radius_outlier(nb_points=MIN_POINTS, \
radius=R): kept if more than MIN_POINTS points (the point itself included) lie strictly within R. Both judge density, not distance from a surface: an omnidirectional scan's slices are sparse far away (spaced by range × the mirror step), so they thin far walls before they remove outliers there (--statistical 20,2.0 took 38 % of a 900 mm wall's true points in its sparsest band, and kept 213 of 276 points 3 mm off it); crop by --crop-range first, or voxel first to even the density.",
    after_help = "Examples:\n  \
omni-merge points.jsonl -o cloud.ply\n  \
omni-merge --voxel 1.0 --statistical 20,2.0 a.jsonl b.jsonl old.ply -o room.ply\n  \
omni-merge --poses odometry.jsonl --crop-range 100,3000 walk.jsonl -o walk.ply\n  \
omni-triangulate ... | omni-merge --radius 5,4 - -o cloud.ply --ascii\n  \
omni-merge points.jsonl -o cloud.las --units m\n  \
omni-merge --voxel 2 points.jsonl -o cloud.pcd --normals --rosbag merged_bag\n\n\
Voxels are anchored at the world origin and the output is ordered by voxel index (deterministic).\n\
Exit codes: 0 ok, 1 bad input or I/O error (nothing half-written), 2 usage error; a signal (Ctrl-C, kill) ends it once its temporary files are removed, and the shell sees 128 + the signal's number (130 for Ctrl-C)."
)]
struct Args {
    /// Inputs: point streams (`-` = stdin) or PLY files (*.ply).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output cloud: .ply, .pcd or .las (`-` = stdout, PLY unless --format). Needed unless
    /// --rosbag is given.
    #[arg(short, long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    cloud: CloudOutputArgs,
    /// Odometry (JSON Lines poses with timestamps) to place each frame in the world.
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Longest odometry gap (ms) that may be interpolated across.
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true)]
    max_pose_gap_ms: f64,
    /// Voxel edge length (mm): each occupied voxel becomes the centroid of its points, scalar
    /// fields averaged (Open3D voxel_down_sample semantics; grid anchored at the world origin).
    #[arg(long, value_name = "SIZE", allow_negative_numbers = true)]
    voxel: Option<f64>,
    /// Statistical outlier removal: K neighbours, STD_RATIO.
    #[arg(long, value_name = "K,STD_RATIO", allow_hyphen_values = true)]
    statistical: Option<String>,
    /// Radius outlier removal: radius R (mm), MIN_POINTS other points.
    #[arg(long, value_name = "R,MIN_POINTS", allow_hyphen_values = true)]
    radius: Option<String>,
    /// Keep points inside the box (mm, world frame).
    #[arg(long, value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX", allow_hyphen_values = true)]
    crop_box: Option<String>,
    /// Keep points measured at a range (distance from the viewpoint, mm) in [MIN, MAX].
    #[arg(long, value_name = "MIN,MAX", allow_hyphen_values = true)]
    crop_range: Option<String>,
    /// Print the point counts of each stage to stderr as JSON.
    #[arg(long)]
    stats: bool,
    /// Keep frames whose `seq` repeats within one stream, and an input file given twice (refused
    /// by default: a stream concatenated or named twice, or a repeated frame, would count its
    /// points twice).
    #[arg(long)]
    allow_duplicates: bool,
    /// Refuse a stream cut short upstream: without its final status record, or marked incomplete
    /// by it (an interrupted scan, a tool that failed); without it the tool warns and goes on.
    #[arg(long)]
    strict: bool,
}

/// Parses `n` comma-separated numbers for option `opt`.
fn numbers(opt: &str, s: &str, n: usize) -> Result<Vec<f64>, CliError> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| CliError::usage(format!("--{opt}: expected {n} comma-separated numbers, got {s:?}")))?;
    if v.len() != n || !v.iter().all(|x| x.is_finite()) {
        return Err(CliError::usage(format!("--{opt}: expected {n} comma-separated numbers, got {s:?}")));
    }
    Ok(v)
}

fn count(opt: &str, x: f64) -> Result<usize, CliError> {
    if x >= 1.0 && x.fract() == 0.0 && x < 1e9 {
        Ok(x as usize)
    } else {
        Err(CliError::usage(format!("--{opt}: the count must be a positive integer, got {x}")))
    }
}

fn options(args: &Args) -> Result<MergeOptions, CliError> {
    let statistical = match &args.statistical {
        Some(s) => {
            let v = numbers("statistical", s, 2)?;
            Some((count("statistical", v[0])?, v[1]))
        }
        None => None,
    };
    let radius = match &args.radius {
        Some(s) => {
            let v = numbers("radius", s, 2)?;
            Some((count("radius", v[1])?, v[0]))
        }
        None => None,
    };
    let crop_box = match &args.crop_box {
        Some(s) => {
            let v = numbers("crop-box", s, 6)?;
            Some(CropBox::new([v[0], v[1], v[2]], [v[3], v[4], v[5]]).map_err(CliError::usage)?)
        }
        None => None,
    };
    let crop_range = match &args.crop_range {
        Some(s) => {
            let v = numbers("crop-range", s, 2)?;
            Some((v[0], v[1]))
        }
        None => None,
    };
    if let Some((_, r)) = statistical
        && !(r > 0.0)
    {
        return Err(CliError::usage("--statistical: STD_RATIO must be positive"));
    }
    if let Some((_, r)) = radius
        && !(r > 0.0)
    {
        return Err(CliError::usage("--radius: R must be positive"));
    }
    // Each point's normal faces the viewpoint its own frame was seen from.
    let viewpoints = args.cloud.normals;
    Ok(MergeOptions { voxel: args.voxel, statistical, radius, crop_box, crop_range, viewpoints })
}

/// The first input file named twice (the same file by its canonical path; stdin and files that
/// cannot be resolved are left to the readers).
fn given_twice(inputs: &[PathBuf]) -> Option<&PathBuf> {
    let mut seen = std::collections::HashSet::new();
    inputs.iter().find(|p| p.as_os_str() != "-" && p.canonicalize().is_ok_and(|c| !seen.insert(c)))
}

fn is_ply(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply"))
}

fn main() -> std::process::ExitCode {
    omni_cli::main("omni-merge", || {
        let args = omni_cli::parse_args::<Args>()?;
        let opts = options(&args)?;
        args.cloud.check().map_err(CliError::usage)?;
        match &args.output {
            Some(o) => {
                args.cloud.format_for(o).map_err(CliError::usage)?;
            }
            None if args.cloud.rosbag.is_none() => return Err(CliError::usage("give -o FILE, --rosbag DIR or both")),
            None => {}
        }
        if args.inputs.iter().filter(|p| p.as_os_str() == "-").count() > 1 {
            return Err(CliError::usage("stdin (`-`) can be given only once"));
        }
        if let Some(twice) = given_twice(&args.inputs).filter(|_| !args.allow_duplicates) {
            return Err(CliError::usage(format!(
                "{}: given twice (its points would be merged twice; --allow-duplicates keeps both)",
                twice.display()
            )));
        }
        if !(args.max_pose_gap_ms >= 0.0 && args.max_pose_gap_ms.is_finite()) {
            return Err(CliError::usage("--max-pose-gap-ms must be a non-negative number"));
        }
        let trajectory = match &args.poses {
            Some(p) => {
                let samples = omni_formats::odometry::read_odometry(p)?;
                let gap_us = (args.max_pose_gap_ms * 1000.0).round() as u64;
                Some(Trajectory::new(&samples, gap_us).map_err(|m| format!("{}: {m}", p.display()))?)
            }
            None => None,
        };
        let mut merger = Merger::new(opts).map_err(CliError::usage)?;
        let mut latest_us: Option<u64> = None;
        for input in &args.inputs {
            let name = omni_formats::io::display_name(input, "stdin");
            if is_ply(input) {
                if trajectory.is_some() {
                    return Err(CliError::new(format!(
                        "{name}: --poses needs point streams (a PLY cloud has no frame timestamps)"
                    )));
                }
                if args.cloud.normals {
                    omni_cli::warn(
                        "omni-merge",
                        &format!(
                            "{name}: a PLY cloud carries no viewpoint, so its normals face the origin; merge omni-triangulate's point stream instead for normals that face where its rays start"
                        ),
                    );
                }
                add_ply(&mut merger, input, &name)?;
            } else {
                let latest = add_stream(&mut merger, input, &name, trajectory.as_ref(), &args)?;
                latest_us = latest_us.max(latest);
            }
        }
        let (mut cloud, stats, viewpoints) = merger.finish_with_viewpoints()?;
        if cloud.is_empty() {
            omni_cli::warn("omni-merge", "no points left after cropping and filtering; writing an empty cloud");
        }
        let seen_from = viewpoints.as_deref().map_or(Viewpoints::Fixed([0.0; 3]), Viewpoints::PerPoint);
        // One stream's frame numbers name its stripes; several streams may repeat them, and a
        // voxel's are means.
        let frames_are_stripes = args.inputs.len() == 1 && args.voxel.is_none();
        if let Some(warning) = args.cloud.finish_cloud_seen_from(&mut cloud, seen_from, frames_are_stripes)? {
            omni_cli::warn("omni-merge", &warning);
        }
        if args.cloud.rosbag.is_some() && latest_us.is_none() {
            omni_cli::warn(
                "omni-merge",
                "no input frame has a timestamp_us (PLY clouds, simulated scans): the bag's cloud is stamped 0",
            );
        }
        let message = BagMessage { stamp_ns: latest_us.unwrap_or(0) * 1000, points: 0..cloud.len() };
        args.cloud.write(&cloud, args.output.as_deref(), &[message], "map")?;
        if args.stats {
            eprintln!("{}", serde_json::to_string(&stats).unwrap_or_default());
        }
        Ok(())
    })
}

fn add_ply(merger: &mut Merger, path: &Path, name: &str) -> Result<(), CliError> {
    let merger = std::cell::RefCell::new(merger);
    omni_cloud::ply_stream::for_each_vertex_typed(
        path,
        &mut |names, types, n| {
            if n == 0 {
                return Err(format!("{name}: the PLY has no vertices"));
            }
            merger.borrow_mut().begin_typed_input(names, types).map_err(|m| format!("{name}: {m}"))
        },
        &mut |p, s| merger.borrow_mut().add(p, s).map_err(|m| format!("{name}: {m}")),
    )?;
    Ok(())
}

fn add_stream(
    merger: &mut Merger,
    path: &Path,
    name: &str,
    traj: Option<&Trajectory>,
    args: &Args,
) -> Result<Option<u64>, CliError> {
    let mut reader = StreamReader::new(omni_formats::io::open_input(path)?, name);
    merger.begin_stream_input().map_err(|m| format!("{name}: {m}"))?;
    let mut frames = 0u64;
    let mut latest_us: Option<u64> = None;
    // The line of each frame seq seen, to refuse repeats.
    let mut seen: std::collections::HashMap<u64, usize> = std::collections::HashMap::new();
    while let Some(record) = reader.next_record()? {
        let frame = match record {
            Record::Frame(frame) => frame,
            Record::Header(h) => {
                merger.set_stream_viewpoint(h.viewpoint_mm.unwrap_or([0.0; 3]));
                continue;
            }
            Record::Status(s) if !s.complete => {
                let msg = format!("{name}: the stream is marked incomplete ({:?})", s.errors);
                if args.strict {
                    return Err(CliError::new(format!("{msg}; refused with --strict")));
                }
                omni_cli::warn("omni-merge", &msg);
                continue;
            }
            _ => continue,
        };
        let loc = format!("{name}: line {} (frame {})", reader.line(), frame.seq);
        if let Some(first) = seen.insert(frame.seq, reader.line())
            && !args.allow_duplicates
        {
            return Err(CliError::new(format!(
                "{loc}: field seq: frame {} already came at line {first} (a repeated frame or stream? --allow-duplicates keeps both)",
                frame.seq
            )));
        }
        let pose = match traj {
            Some(t) => {
                let ts = frame.timestamp_us.ok_or_else(|| format!("{loc}: no timestamp_us, needed with --poses"))?;
                Some(t.pose_at(ts).map_err(|m| format!("{loc}: {m}"))?)
            }
            None => None,
        };
        merger.add_frame(&frame, pose.as_ref()).map_err(|m| format!("{loc}: {m}"))?;
        latest_us = latest_us.max(frame.timestamp_us);
        frames += 1;
    }
    if frames == 0 {
        return Err(CliError::new(format!("{name}: no frame records")));
    }
    if reader.cut_short() {
        let msg = reader.cut_short_message();
        if args.strict {
            return Err(CliError::new(format!("{msg}; refused with --strict")));
        }
        omni_cli::warn("omni-merge", &format!("{msg}; its frames are merged, the cloud may be partial"));
    }
    Ok(latest_us)
}
