//! omni-triangulate: stripe stream → 3D points (stream with `points` added, or PLY).

use clap::Parser;
use omni_cli::CliError;
use omni_cloud::cloud::{append_frame_points, empty_point_cloud};
use omni_cloud::export::{BagGrouping, CloudOutputArgs, FrameSpan, bag_messages, frame_stamp_ns};
use omni_cloud::normals::Viewpoints;
use omni_cloud::triangulate::{DEFAULT_MIN_INCIDENCE_DEG, Rejections, Triangulator};
use omni_formats::export::CloudFormat;
use omni_formats::ply::PointCloud;
use omni_formats::rosbag::{BagImage, BagImages, camera_info, camera_info_topic};
use omni_formats::stream::{Header, Record, Status, StreamReader, StreamWriter, resolve_frames_dir};
use omni_formats::{CameraFile, ScannerFile};
use std::io::Write;
use std::path::PathBuf;

const PRODUCER: &str = concat!("omni-triangulate ", env!("CARGO_PKG_VERSION"));

#[derive(Parser, Debug)]
#[command(
    // Help is printed as written, unwrapped: examples stay one line for copy and paste.
    term_width = 0,
    version,
    about = "Triangulate stripe points: each stripe pixel's ray meets its frame's laser light plane.",
    long_about = "Reads the stripe stream written by omni-ridge (JSON Lines), intersects every stripe \
pixel's ray (from camera.json) with the light plane of each laser that was on in that frame (from \
scanner.json), and keeps the intersection that is in front of the viewpoint and lit by that laser. \
Rays meeting the plane at less than --min-incidence-deg are refused: the range error grows as \
1/sin(angle). Writes the stream with a `points` array added to each frame \
([x, y, z, laser, range, stripe_index], mm, world = receiver frame), and/or a point cloud (PLY, PCD or \
LAS by the extension, or --format), and/or a ROS 2 bag (--rosbag) with one \
sensor_msgs/msg/PointCloud2 per frame or per revolution, stamped with the frames' timestamp_us; with \
--rosbag-images the bag also holds every frame's image as sensor_msgs/msg/Image and the receiver model \
as sensor_msgs/msg/CameraInfo.",
    after_help = "Examples:\n  \
omni-ridge scan.jsonl | omni-triangulate --camera camera.json --scanner scanner.json > points.jsonl\n  \
omni-triangulate --camera camera.json --scanner scanner.json ridges.jsonl -o cloud.ply\n  \
omni-triangulate --camera camera.json --scanner scanner.json ridges.jsonl -o points.jsonl --cloud cloud.pcd\n  \
omni-triangulate --camera camera.json --scanner scanner.json ridges.jsonl --rosbag scan_bag --bag-per revolution\n  \
omni-triangulate --camera camera.json --scanner scanner.json ridges.jsonl --rosbag scan_bag --rosbag-images\n\n\
PLY scalar fields: intensity, scalar_frame, scalar_laser, scalar_alpha_deg, scalar_range (mm), scalar_u, scalar_v (px).\n\
Exit codes: 0 ok, 1 bad input or I/O error (nothing half-written), 2 usage error; a signal (Ctrl-C, kill) ends it once its temporary files are removed, and the shell sees 128 + the signal's number (130 for Ctrl-C)."
)]
struct Args {
    /// Receiver model (camera.json).
    #[arg(long)]
    camera: PathBuf,
    /// Transmitter model (scanner.json).
    #[arg(long)]
    scanner: PathBuf,
    /// Stripe stream (JSON Lines); `-` = stdin.
    #[arg(default_value = "-")]
    input: PathBuf,
    /// Output: a stream (`-` = stdout, default) or, if the name ends in .ply, .pcd or .las, a
    /// point cloud.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Also (or only, without -o) write the points as a cloud: PLY, PCD or LAS by the
    /// extension or --format.
    #[arg(long, visible_alias = "ply", value_name = "FILE")]
    cloud: Option<PathBuf>,
    #[command(flatten)]
    cloud_out: CloudOutputArgs,
    /// Bag messages: one PointCloud2 per frame or per revolution.
    #[arg(long, value_enum, default_value_t = BagGrouping::Frame)]
    bag_per: BagGrouping,
    /// Also put every frame's image into the bag (--rosbag): sensor_msgs/msg/Image, mono8 or
    /// mono16 as the file is (colour frames as their luma), stamped as the frame, and the
    /// receiver model (--camera) as sensor_msgs/msg/CameraInfo beside each (docs/FORMATS.md).
    #[arg(long)]
    rosbag_images: bool,
    /// The bag's image topic; the CameraInfo goes on `camera_info` in its namespace.
    #[arg(long, value_name = "NAME", default_value = "/omniscan/image_raw")]
    image_topic: String,
    /// Stamp frames that have no timestamp_us (simulated scans) seq × MS milliseconds.
    #[arg(long, value_name = "MS")]
    stamp_period_ms: Option<f64>,
    /// Smallest accepted angle between a ray and the light plane (degrees).
    #[arg(long, default_value_t = DEFAULT_MIN_INCIDENCE_DEG, allow_negative_numbers = true)]
    min_incidence_deg: f64,
    /// Refuse an input stream without its final status record (cut short upstream); without
    /// it the tool warns and passes `complete: false` on.
    #[arg(long)]
    strict: bool,
    /// Write the stream's stripe and point arrays in binary after each frame's line (stream
    /// version 2): the same numbers bit for bit, far cheaper to write and read through a pipe.
    /// Every omniscan tool and the Python package read both; text tools (jq) read JSON only.
    #[arg(long)]
    binary: bool,
}

fn main() -> std::process::ExitCode {
    omni_cli::main("omni-triangulate", || {
        let args = omni_cli::parse_args::<Args>()?;
        let (camera_file, camera) = CameraFile::load(&args.camera)?;
        let (scanner_file, transmitter) = ScannerFile::load(&args.scanner)?;
        let tri = Triangulator::new(camera.as_ref(), &transmitter, args.min_incidence_deg).map_err(CliError::usage)?;
        args.cloud_out.check().map_err(CliError::usage)?;
        if let Some(p) = args.stamp_period_ms {
            omni_cli::positive("--stamp-period-ms", p)?;
        }
        let bag = args.cloud_out.rosbag.is_some();
        if args.rosbag_images && !bag {
            return Err(CliError::usage("--rosbag-images needs --rosbag DIR"));
        }
        if !args.image_topic.starts_with('/') || args.image_topic.ends_with('/') {
            return Err(CliError::usage(format!(
                "--image-topic: a ROS topic name starts with `/`, got {:?}",
                args.image_topic
            )));
        }
        let (stream_out, mut cloud_out) = match (&args.output, &args.cloud) {
            (Some(o), p) if CloudFormat::has_cloud_extension(o) => {
                if p.is_some() {
                    return Err(CliError::usage("-o names a cloud file; give --cloud only with a stream output"));
                }
                (None, Some(o.clone()))
            }
            (Some(o), p) => (Some(o.clone()), p.clone()),
            (None, Some(p)) => (None, Some(p.clone())),
            (None, None) if bag => (None, None),
            (None, None) => (Some(PathBuf::from("-")), None),
        };
        if let Some(path) = &cloud_out {
            args.cloud_out.format_for(path).map_err(CliError::usage)?;
        }
        let stdout = |p: &Option<PathBuf>| p.as_deref() == Some(std::path::Path::new("-"));
        if stdout(&stream_out) && stdout(&cloud_out) {
            return Err(CliError::usage("the stream and the cloud cannot both go to stdout (-)"));
        }
        let mut cloud = (cloud_out.is_some() || bag).then(empty_point_cloud);
        let input = omni_formats::io::open_input(&args.input)?;
        let name = omni_formats::io::display_name(&args.input, "stdin");
        // Relative frames_dir: against the stream file's directory (as omni-ridge reads it).
        let base_dir = match args.input.parent() {
            Some(p) if args.input != std::path::Path::new("-") && !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut run = Run {
            base_dir,
            frames_dir: None,
            images: Vec::new(),
            viewpoint_mm: camera_file.model.viewpoint_mm(),
            unobserved: scanner_file.unobserved(),
            facet_offsets: match &transmitter {
                omni_model::TransmitterModel::Polygon(tx) => {
                    let n = tx.num_facets();
                    Some((n, tx.params().lasers.iter().map(|l| l.facet_offset % n).collect()))
                }
                omni_model::TransmitterModel::FixedPlanes(_) => None,
            },
            uncalibrated_frames: 0,
            tri: &tri,
            args: &args,
            cloud: cloud.as_mut(),
            rejections: Rejections::default(),
            points: 0,
            frames: 0,
            spans: Vec::new(),
        };
        // Every output is written in full first and put in place together at the end: a run
        // that fails on one of them leaves none.
        let mut staged = Vec::new();
        match &stream_out {
            Some(path) => {
                // The closure's error only aborts the write; the message is kept here.
                let mut failure = None;
                let out_name = omni_formats::io::display_name(path, "stdout");
                let written = omni_formats::io::write_staged(path, |w| {
                    run.process(input, &name, Some((w, &out_name))).map_err(|m| {
                        failure = Some(m);
                        std::io::Error::other("aborted")
                    })
                });
                if let Some(m) = failure {
                    return Err(CliError::new(m));
                }
                staged.push(written?);
            }
            None => run.process(input, &name, None).map_err(CliError::new)?,
        }
        let spans = std::mem::take(&mut run.spans);
        let frames = std::mem::take(&mut run.images);
        if let Some(mut cloud) = cloud {
            let period_us = args.stamp_period_ms.map(|ms| ms * 1000.0);
            let in_input = |m: String| CliError::new(format!("{name}: {m}"));
            let messages =
                if bag { bag_messages(&spans, args.bag_per, period_us).map_err(in_input)? } else { Vec::new() };
            let seen_from = Viewpoints::Fixed(camera_file.model.viewpoint_mm());
            if let Some(warning) = args.cloud_out.finish_cloud_seen_from(&mut cloud, seen_from, true)? {
                omni_cli::warn("omni-triangulate", &warning);
            }
            let mut load = |i: usize| {
                let g = omni_vision::image_io::load_gray(&frames[i].2)?;
                Ok(BagImage { width: g.width, height: g.height, bit_depth: g.bit_depth, samples: g.data })
            };
            let mut images = match args.rosbag_images {
                true => Some(BagImages {
                    topic: args.image_topic.clone(),
                    info_topic: camera_info_topic(&args.image_topic),
                    stamps_ns: frames
                        .iter()
                        .map(|(seq, ts, _)| frame_stamp_ns(*seq, *ts, period_us))
                        .collect::<Result<_, _>>()
                        .map_err(in_input)?,
                    load: &mut load,
                    camera_info: Some(camera_info(&camera_file.model)),
                }),
                false => None,
            };
            staged.extend(args.cloud_out.stage(
                &cloud,
                cloud_out.take().as_deref(),
                &messages,
                images.as_mut(),
                "omniscan",
            )?);
        }
        omni_formats::io::commit_all(staged)?;
        Ok(())
    })
}

struct Run<'a> {
    /// The directory a relative `frames_dir` is resolved against.
    base_dir: PathBuf,
    /// The header's frames directory, resolved.
    frames_dir: Option<String>,
    /// Where the camera's rays start (mm, sensor frame; a catadioptric camera's mirror focus).
    viewpoint_mm: [f64; 3],
    /// The facets and lasers the scanner file's calibration never saw ([`ScannerFile::unobserved`]).
    unobserved: (Vec<u32>, Vec<u32>),
    /// Frames with points from those facets or lasers.
    uncalibrated_frames: u64,
    /// A polygon's facet count and each laser's facet offset: laser j reflects off facet
    /// (frame facet + offset j) mod n, the facet the calibration report names.
    facet_offsets: Option<(u32, Vec<u32>)>,
    /// Each frame's seq, timestamp and image file (for --rosbag-images).
    images: Vec<(u64, Option<u64>, PathBuf)>,
    tri: &'a Triangulator<'a>,
    args: &'a Args,
    cloud: Option<&'a mut PointCloud>,
    rejections: Rejections,
    /// Points written so far.
    points: u64,
    /// Frames read so far.
    frames: u64,
    /// Each frame's points in the cloud (for the bag's messages).
    spans: Vec<FrameSpan>,
}

impl Run<'_> {
    /// Reads every record, triangulates frames, writes records to `out` (writer and its name)
    /// if any. The error is the one-line message naming the file and record at fault.
    fn process(
        &mut self,
        input: Box<dyn std::io::BufRead>,
        name: &str,
        out: Option<(&mut dyn Write, &str)>,
    ) -> Result<(), String> {
        let fail = |m: String| m;
        let mut reader = StreamReader::new(input, name);
        let mut writer = out.map(|(w, n)| StreamWriter::new(w, n).binary(self.args.binary));
        let mut first = true;
        while let Some(record) = reader.next_record().map_err(|e| fail(e.to_string()))? {
            let record = match record {
                Record::Header(h) => {
                    self.frames_dir = h.frames_dir.as_deref().map(|d| resolve_frames_dir(&self.base_dir, d));
                    Record::Header(self.header(h))
                }
                Record::Frame(mut frame) => {
                    if self.args.rosbag_images {
                        let path = frame.resolve_path(self.frames_dir.as_deref(), &frame.path);
                        self.images.push((frame.seq, frame.timestamp_us, path));
                    }
                    let loc = format!("{name}: line {} (frame {})", reader.line(), frame.seq);
                    let res = self.tri.triangulate_frame(&frame).map_err(|m| fail(format!("{loc}: {m}")))?;
                    self.rejections.add(&res.rejections);
                    if res.points.iter().any(|p| self.uncalibrated(frame.facet, p.laser)) {
                        self.uncalibrated_frames += 1;
                    }
                    self.points += res.points.len() as u64;
                    self.frames += 1;
                    frame.points = Some(res.points);
                    if let Some(cloud) = self.cloud.as_deref_mut() {
                        let start = cloud.len();
                        append_frame_points(cloud, &frame, None, &|_| true).map_err(|m| fail(format!("{loc}: {m}")))?;
                        self.spans.push(FrameSpan {
                            seq: frame.seq,
                            revolution: frame.revolution,
                            timestamp_us: frame.timestamp_us,
                            points: start..cloud.len(),
                        });
                    }
                    Record::Frame(frame)
                }
                Record::Status(status) => Record::Status(self.status(status)),
                other => other,
            };
            if let Some(w) = writer.as_mut() {
                if first && !matches!(record, Record::Header(_)) {
                    w.write(&Record::Header(self.header(Header::new("unknown")))).map_err(|e| fail(e.to_string()))?;
                }
                w.write(&record).map_err(|e| fail(e.to_string()))?;
            }
            first = false;
        }
        if let Some(w) = writer.as_mut()
            && first
        {
            w.write(&Record::Header(self.header(Header::new("unknown")))).map_err(|e| fail(e.to_string()))?;
        }
        if reader.cut_short() {
            let msg = reader.cut_short_message();
            if self.args.strict {
                return Err(format!("{msg}; refused with --strict"));
            }
            omni_cli::warn("omni-triangulate", &format!("{msg}; passing on complete: false"));
            if let Some(w) = writer.as_mut() {
                w.write(&Record::Status(self.status(Status::cut_short(self.frames, msg))))
                    .map_err(|e| fail(e.to_string()))?;
            }
        }
        self.check_the_camera_fits(name)?;
        self.warn_of_uncalibrated_planes(name);
        if let Some(w) = writer.as_mut() {
            w.flush().map_err(|e| fail(e.to_string()))?;
        }
        Ok(())
    }

    /// Whether laser `laser`'s light plane in a frame whose laser 0 faces `facet` is one the
    /// scanner's calibration never saw: the laser, or the facet it reflects off.
    fn uncalibrated(&self, facet: u32, laser: u32) -> bool {
        let (facets, lasers) = &self.unobserved;
        let reflected = self.facet_offsets.as_ref().and_then(|(n, offsets)| {
            let offset = offsets.get(laser as usize)?;
            Some((facet % n + offset) % n)
        });
        lasers.contains(&laser) || reflected.is_some_and(|k| facets.contains(&k))
    }

    /// Warns where frames took points from facets or lasers the scanner's calibration never saw:
    /// their light planes are the initial ones, off by up to millimetres on a real build.
    fn warn_of_uncalibrated_planes(&self, name: &str) {
        if self.uncalibrated_frames == 0 {
            return;
        }
        let list = |v: &[u32]| v.iter().map(u32::to_string).collect::<Vec<_>>().join(", ");
        let (facets, lasers) = &self.unobserved;
        omni_cli::warn(
            "omni-triangulate",
            &format!(
                "{name}: {} frame(s) took points from light planes {} never calibrated (facets not seen on its rig: [{}], lasers: [{}]; kept at their initial values): calibrate with frames of every facet and laser the scan uses",
                self.uncalibrated_frames,
                self.args.scanner.display(),
                list(facets),
                list(lasers)
            ),
        );
    }

    /// Refuses a run in which no stripe pixel gives a point, and warns where most map to no
    /// ray of the camera: the frames were taken with another camera (another image size,
    /// another sensor's mirror) or scanner, which would otherwise pass as a scan that saw
    /// nothing.
    fn check_the_camera_fits(&self, name: &str) -> Result<(), String> {
        let no_ray = self.rejections.no_ray;
        let pixels = self.points + self.rejections.refused();
        let camera = self.args.camera.display();
        // Every pixel without a ray (none made a point, none was refused otherwise).
        if no_ray > 0 && no_ray == pixels {
            return Err(format!(
                "{name}: none of its {pixels} stripe pixels maps to a ray of {camera}: were the frames taken with this camera?"
            ));
        }
        // Every pixel refused: rays that meet no light plane where it lights them are the
        // other sensor's (another mirror, size or scanner file); a scan of a real scene keeps
        // most of its stripe.
        if pixels > 0 && self.points == 0 {
            let r = &self.rejections;
            let cause = if 2 * r.grazing > pixels {
                format!("is --min-incidence-deg {} too strict?", self.args.min_incidence_deg)
            } else {
                "are they the frames' sensor files?".to_string()
            };
            return Err(format!(
                "{name}: none of its {pixels} stripe pixels gives a point ({} with no ray, {} unlit by any light plane, {} grazing) with {camera} and {}: {cause}",
                r.no_ray,
                r.unlit,
                r.grazing,
                self.args.scanner.display()
            ));
        }
        if 2 * no_ray > pixels {
            omni_cli::warn(
                "omni-triangulate",
                &format!(
                    "{name}: {no_ray} of {pixels} stripe pixels map to no ray of {camera}: is it the frames' camera?"
                ),
            );
        }
        Ok(())
    }

    /// The status record passed on, with what this stage refused next to the upstream counts.
    fn status(&self, mut status: Status) -> Status {
        let r = &self.rejections;
        status.extra.insert(
            "triangulate".into(),
            serde_json::json!({"points": self.points, "no_ray": r.no_ray, "grazing": r.grazing,
                "unlit": r.unlit, "ambiguous": r.ambiguous}),
        );
        status
    }

    fn header(&self, mut h: Header) -> Header {
        if h.producers == ["unknown"] {
            h.producers.clear();
        }
        h.producers.push(PRODUCER.into());
        h.camera = Some(self.args.camera.display().to_string());
        h.scanner = Some(self.args.scanner.display().to_string());
        h.viewpoint_mm = Some(self.viewpoint_mm);
        h.extra.insert("min_incidence_deg".into(), self.args.min_incidence_deg.into());
        h
    }
}
