//! The cloud-output options shared by `omni-merge` and `omni-triangulate` (format, coordinate
//! type and unit, normals, ROS 2 bag), and the grouping of frames into bag messages.

use crate::normals::{Viewpoints, add_normals_seen_from};
use omni_formats::export::{CloudFormat, CloudOptions, Units, write_cloud_staged};
use omni_formats::io::Staged;
use omni_formats::ply::PointCloud;
use omni_formats::rosbag::{BagImages, BagMessage, BagOptions, write_rosbag_staged};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Command-line options for the cloud a tool writes (flattened into its arguments).
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct CloudOutputArgs {
    /// Point-cloud format: ply, pcd (PCL) or las (LAS 1.4). Default: the output's extension
    /// (.ply, .pcd, .las; any other is an error); `-` (stdout) is PLY.
    #[arg(long, value_name = "FORMAT", value_parser = CloudFormat::parse)]
    pub format: Option<CloudFormat>,
    /// Write ASCII instead of binary (PLY and PCD; LAS is always binary).
    #[arg(long)]
    pub ascii: bool,
    /// Coordinates as float64 instead of float32 (PLY, PCD and the bag's x y z).
    #[arg(long)]
    pub double: bool,
    /// Coordinate unit of the cloud file, m or mm (recorded in a PLY/PCD comment; LAS scale
    /// 0.01 mm either way). Scalar fields keep their units (scalar_range stays mm). Bags are
    /// always metres.
    #[arg(long, value_name = "m|mm", default_value = "mm", value_parser = Units::parse)]
    pub units: Units,
    /// Add normals nx ny nz (PCD and bags: normal_x …): the plane fitted to each point's
    /// --normal-neighbours nearest points, turned to face the point its ray started from (the
    /// camera's viewpoint, a catadioptric camera's mirror focus; with omni-merge --poses, moved
    /// to where the sensor was when it took the point's frame; a PLY input carries none: the
    /// origin). Where the neighbours lie along one stripe (one frame's cloud), the plane is
    /// undetermined: those normals are across the stripe towards the sensor, and a warning
    /// counts them.
    #[arg(long)]
    pub normals: bool,
    /// Neighbours (the point itself counted) of the normals' plane fit.
    #[arg(long, value_name = "K", default_value_t = 16)]
    pub normal_neighbours: usize,
    /// Also write a ROS 2 bag: directory DIR (must not exist) with DIR_0.mcap and
    /// metadata.yaml, sensor_msgs/msg/PointCloud2 in metres (`ros2 bag play DIR`; Foxglove
    /// opens the .mcap).
    #[arg(long, value_name = "DIR")]
    pub rosbag: Option<PathBuf>,
    /// The bag's topic.
    #[arg(long, value_name = "NAME", default_value = "/omniscan/points")]
    pub topic: String,
    /// The messages' header.frame_id (default: `omniscan` for the sensor frame, `map` for
    /// omni-merge's world frame).
    #[arg(long, value_name = "ID")]
    pub frame_id: Option<String>,
    /// MCAP chunk size target (KiB); a larger message gets a chunk of its own.
    #[arg(long, value_name = "KIB", default_value_t = 1024)]
    pub chunk_kib: u64,
}

impl CloudOutputArgs {
    /// Checks the combinations clap cannot.
    pub fn check(&self) -> Result<(), String> {
        if self.normals && self.normal_neighbours < 3 {
            return Err(format!("--normal-neighbours: at least 3, got {}", self.normal_neighbours));
        }
        if self.chunk_kib == 0 {
            return Err("--chunk-kib must be positive".into());
        }
        if self.topic.is_empty() || !self.topic.starts_with('/') {
            return Err(format!("--topic: a ROS topic name starts with `/`, got {:?}", self.topic));
        }
        Ok(())
    }

    pub fn cloud_options(&self) -> CloudOptions {
        CloudOptions { ascii: self.ascii, double: self.double, units: self.units }
    }

    pub fn bag_options(&self, default_frame_id: &str) -> BagOptions {
        BagOptions {
            topic: self.topic.clone(),
            frame_id: self.frame_id.clone().unwrap_or_else(|| default_frame_id.to_string()),
            chunk_size: self.chunk_kib * 1024,
            double: self.double,
        }
    }

    /// The format of the cloud file `path` (the extension or --format), checked before any work.
    pub fn format_for(&self, path: &Path) -> Result<CloudFormat, String> {
        CloudFormat::for_output(path, self.format)
    }

    /// Adds normals if asked for, each facing the viewpoint its point was seen from (mm, the
    /// cloud's frame); `frames_are_stripes` as in [`add_normals_seen_from`]. Returns a warning
    /// for the user when some points' neighbourhoods lie along a line, whose normals only face
    /// across it ([`crate::normals::Normals`]).
    pub fn finish_cloud_seen_from(
        &self,
        cloud: &mut PointCloud,
        viewpoints: Viewpoints<'_>,
        frames_are_stripes: bool,
    ) -> Result<Option<String>, String> {
        if !self.normals {
            return Ok(None);
        }
        let along_a_line = add_normals_seen_from(cloud, self.normal_neighbours, viewpoints, frames_are_stripes)?;
        Ok((along_a_line > 0).then(|| {
            format!(
                "{along_a_line} of {} points' {} nearest neighbours lie along a line (one stripe): their normals are across it, towards the sensor, but the surface's tilt about the stripe is not measured; merge more frames (or, where slices lie farther apart than the neighbours reach, raise --normal-neighbours)",
                cloud.len(),
                self.normal_neighbours
            )
        }))
    }

    /// Writes the cloud file (if `path`) and the bag (if --rosbag) with `messages`, both put
    /// in place only once both are written.
    pub fn write(
        &self,
        cloud: &PointCloud,
        path: Option<&Path>,
        messages: &[BagMessage],
        default_frame_id: &str,
    ) -> Result<(), String> {
        let staged = self.stage(cloud, path, messages, None, default_frame_id)?;
        omni_formats::io::commit_all(staged).map_err(|e| e.to_string())
    }

    /// [`CloudOutputArgs::write`] up to putting the outputs in place, with the camera frames in
    /// the bag if `images` is given: each written in full, to be committed with the tool's other
    /// outputs once all of them succeeded.
    pub fn stage(
        &self,
        cloud: &PointCloud,
        path: Option<&Path>,
        messages: &[BagMessage],
        images: Option<&mut BagImages>,
        default_frame_id: &str,
    ) -> Result<Vec<Staged>, String> {
        let mut staged = Vec::new();
        if let Some(path) = path {
            let format = self.format_for(path)?;
            staged.push(write_cloud_staged(path, cloud, format, &self.cloud_options()).map_err(|e| e.to_string())?);
        }
        if let Some(dir) = &self.rosbag {
            let bag = write_rosbag_staged(dir, cloud, messages, images, &self.bag_options(default_frame_id));
            staged.push(bag.map_err(|e| e.to_string())?);
        }
        Ok(staged)
    }
}

/// How frames become bag messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum BagGrouping {
    /// One PointCloud2 per camera frame (one laser stripe's points).
    #[default]
    Frame,
    /// One PointCloud2 per polygon revolution (a full sweep).
    Revolution,
}

/// One frame's points in a cloud built frame by frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameSpan {
    pub seq: u64,
    pub revolution: u64,
    /// The frame's `timestamp_us`, if it has one.
    pub timestamp_us: Option<u64>,
    pub points: Range<usize>,
}

/// A frame's bag stamp (ns): its `timestamp_us`, else `seq × period_us` if a period is given,
/// else an error naming the frame.
pub fn frame_stamp_ns(seq: u64, timestamp_us: Option<u64>, period_us: Option<f64>) -> Result<u64, String> {
    match (timestamp_us, period_us) {
        // In integers: an epoch time in µs has 16 digits, more than an f64 keeps below the µs.
        (Some(t), _) => t.checked_mul(1000).ok_or_else(|| format!("frame {seq}: timestamp_us {t} is beyond 2554")),
        (None, Some(p)) => Ok((seq as f64 * p * 1000.0).round() as u64),
        (None, None) => Err(format!(
            "frame {seq}: no timestamp_us to stamp its bag message with (give --stamp-period-ms for streams without timestamps)"
        )),
    }
}

/// The bag messages of frames (in stream order, contiguous point ranges): one per frame or per
/// revolution (consecutive frames of one revolution; stamped with its first frame), empty ones
/// left out. A frame without `timestamp_us` is stamped `seq × period_us` if a period is given,
/// else refused naming the frame.
pub fn bag_messages(
    frames: &[FrameSpan],
    grouping: BagGrouping,
    period_us: Option<f64>,
) -> Result<Vec<BagMessage>, String> {
    let mut out: Vec<(u64, BagMessage)> = Vec::new();
    for f in frames {
        let stamp_ns = frame_stamp_ns(f.seq, f.timestamp_us, period_us)?;
        match out.last_mut() {
            Some((rev, m))
                if grouping == BagGrouping::Revolution && *rev == f.revolution && m.points.end == f.points.start =>
            {
                m.points.end = f.points.end;
            }
            _ => out.push((f.revolution, BagMessage { stamp_ns, points: f.points.clone() })),
        }
    }
    let mut messages: Vec<BagMessage> = out.into_iter().map(|(_, m)| m).filter(|m| !m.points.is_empty()).collect();
    // Controller timestamps only grow; a stream out of order would make the bag unplayable.
    if let Some(w) = messages.windows(2).find(|w| w[1].stamp_ns < w[0].stamp_ns) {
        return Err(format!("bag messages out of time order ({} ns after {} ns)", w[1].stamp_ns, w[0].stamp_ns));
    }
    messages.shrink_to_fit();
    Ok(messages)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(seq: u64, revolution: u64, t: Option<u64>, points: Range<usize>) -> FrameSpan {
        FrameSpan { seq, revolution, timestamp_us: t, points }
    }

    #[test]
    fn frames_group_per_frame_or_per_revolution() {
        let frames = [
            span(0, 0, Some(10), 0..3),
            span(1, 0, Some(15), 3..3),
            span(2, 0, Some(20), 3..7),
            span(3, 1, Some(30), 7..9),
        ];
        let per_frame = bag_messages(&frames, BagGrouping::Frame, None).unwrap();
        let ranges: Vec<_> = per_frame.iter().map(|m| (m.stamp_ns, m.points.clone())).collect();
        assert_eq!(ranges, [(10_000, 0..3), (20_000, 3..7), (30_000, 7..9)]);
        let per_rev = bag_messages(&frames, BagGrouping::Revolution, None).unwrap();
        let ranges: Vec<_> = per_rev.iter().map(|m| (m.stamp_ns, m.points.clone())).collect();
        assert_eq!(ranges, [(10_000, 0..7), (30_000, 7..9)]);
    }

    #[test]
    fn missing_timestamps_need_a_period() {
        let frames = [span(4, 0, None, 0..2)];
        let e = bag_messages(&frames, BagGrouping::Frame, None).unwrap_err();
        assert!(e.starts_with("frame 4: no timestamp_us"), "{e}");
        let m = bag_messages(&frames, BagGrouping::Frame, Some(5000.0)).unwrap();
        assert_eq!(m[0].stamp_ns, 20_000_000);
    }

    #[test]
    fn epoch_timestamps_keep_their_last_microsecond() {
        // 2024-12-05 in µs has 16 digits: through f64 nanoseconds it came out 88 ns early.
        assert_eq!(frame_stamp_ns(0, Some(1_733_390_000_000_007), None), Ok(1_733_390_000_000_007_000));
        assert_eq!(frame_stamp_ns(1, Some(1_733_390_000_033_340), Some(5.0)), Ok(1_733_390_000_033_340_000));
        assert!(frame_stamp_ns(2, Some(u64::MAX / 100), None).unwrap_err().starts_with("frame 2: timestamp_us"));
    }
}
