//! Live output for robots: frames measured by the pipeline (`omni-ridge | omni-triangulate`)
//! are grouped into sweeps ([`sweep`]) and each sweep is published as soon as its last frame
//! is measured ([`live`]): to ROS 2 over a pure-Rust DDS stack ([`dds`], messages in [`msg`])
//! and to Foxglove ([`foxglove`]).
//! A slow consumer loses its oldest sweeps ([`queue`]); it never holds back capture.

pub mod dds;
pub mod foxglove;
pub mod live;
pub mod msg;
pub mod queue;
pub mod sweep;

pub use live::{FrameFile, FrameRetention, LiveOptions, Published, Sink, Summary};
pub use sweep::{Sweep, SweepAssembler, SweepPoint};

/// The ROS 2 sink: each sweep as a PointCloud2 in `frame_id`.
pub struct DdsSink {
    pub publisher: dds::DdsPublisher,
    pub frame_id: String,
}

impl Sink for DdsSink {
    fn name(&self) -> &str {
        "dds"
    }

    fn publish(&mut self, sweep: &Sweep, _frame: Option<&FrameFile>) -> Result<(), String> {
        if sweep.points.is_empty() {
            return Ok(());
        }
        self.publisher.publish_points(msg::point_cloud2(sweep, &self.frame_id))
    }
}
