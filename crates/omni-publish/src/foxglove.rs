//! A Foxglove WebSocket server (the `foxglove` crate, subprotocol `foxglove.sdk.v1`): the live
//! cloud of each sweep, the sweep's last frame as an image, the calibration and the sensor's
//! transform, so that Foxglove shows the scan as it happens.
//!
//! Channels (under the prefix, default `/omniscan`): `points` (`foxglove.PointCloud`, the same
//! fields and bytes as the ROS 2 cloud), `image` (`foxglove.RawImage`, mono8 or mono16),
//! `calibration` (JSON: camera.json and scanner.json) and `/tf` (`foxglove.FrameTransforms`).
//! Foxglove keeps no latched topics, so the calibration and the transform go out with every
//! sweep (a few kB): a client that connects late has them with its first cloud.

use crate::live::{FrameFile, Sink};
use crate::msg::{CLOUD_FIELDS, POINT_STEP, cloud_data, datatype};
use crate::sweep::Sweep;
use foxglove::messages::{
    FrameTransform, FrameTransforms, PackedElementField, PointCloud, Quaternion, RawImage, Timestamp, Vector3,
    packed_element_field::NumericType,
};
use foxglove::{Channel, Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle};
use nalgebra::Isometry3;
use std::sync::Arc;

/// Where the server listens and what it sends.
#[derive(Debug, Clone)]
pub struct FoxgloveOptions {
    pub host: String,
    /// 0 = any free port (see [`FoxgloveSink::port`]).
    pub port: u16,
    /// Topic prefix, e.g. `/omniscan`.
    pub prefix: String,
    /// The sensor's frame id.
    pub frame_id: String,
    /// The robot's frame, parent of `extrinsics`.
    pub base_frame: String,
    /// Sensor → robot (mm), if known.
    pub extrinsics: Option<Isometry3<f64>>,
    /// camera.json and scanner.json as one JSON object, if given.
    pub calibration: Option<String>,
    /// Sweeps the server keeps waiting for each client; a slower client loses the oldest.
    pub backlog_sweeps: usize,
}

/// Messages one sweep sends: points, image, calibration and `/tf`.
const MESSAGES_PER_SWEEP: usize = 4;

/// The running server and its channels.
pub struct FoxgloveSink {
    server: WebSocketServerHandle,
    points: Channel<PointCloud>,
    image: Channel<RawImage>,
    transforms: Channel<FrameTransforms>,
    calibration: Arc<RawChannel>,
    opts: FoxgloveOptions,
    // Channels log through it; it must outlive them.
    _context: Arc<Context>,
}

impl FoxgloveSink {
    /// Binds and starts the server; a port in use or a bad address is a one-line error.
    pub fn start(opts: FoxgloveOptions) -> Result<Self, String> {
        let context = Context::new();
        let prefix = opts.prefix.trim_end_matches('/').to_string();
        let points = context.channel_builder(format!("{prefix}/points")).build::<PointCloud>();
        let image = context.channel_builder(format!("{prefix}/image")).build::<RawImage>();
        let transforms = context.channel_builder("/tf").build::<FrameTransforms>();
        let calibration = context
            .channel_builder(format!("{prefix}/calibration"))
            .message_encoding("json")
            .schema(Schema::new("omniscan.calibration", "jsonschema", br#"{"type":"object"}"#.as_slice()))
            .build_raw()
            .map_err(|e| format!("Foxglove channel {prefix}/calibration: {e}"))?;
        let server = WebSocketServer::new()
            .name("omniscan")
            .context(&context)
            .bind(opts.host.clone(), opts.port)
            // The server queues messages per client (1024 by default, hundreds of sweeps): a
            // stalled client would get minutes-old clouds and hold their memory.
            .message_backlog_size(MESSAGES_PER_SWEEP * opts.backlog_sweeps.max(1))
            .start_blocking()
            .map_err(|e| format!("--foxglove {}:{}: {e}", opts.host, opts.port))?;
        Ok(FoxgloveSink { server, points, image, transforms, calibration, opts, _context: context })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.server.port()
    }

    fn transform(&self, stamp: Timestamp) -> Option<FrameTransforms> {
        let iso = self.opts.extrinsics?;
        let t = iso.translation.vector / 1000.0;
        let q = iso.rotation;
        Some(FrameTransforms {
            transforms: vec![FrameTransform {
                timestamp: Some(stamp),
                parent_frame_id: self.opts.base_frame.clone(),
                child_frame_id: self.opts.frame_id.clone(),
                translation: Some(Vector3 { x: t.x, y: t.y, z: t.z }),
                rotation: Some(Quaternion { x: q.i, y: q.j, z: q.k, w: q.w }),
            }],
        })
    }
}

fn timestamp(us: u64) -> Timestamp {
    Timestamp::new((us / 1_000_000) as u32, (us % 1_000_000) as u32 * 1000)
}

/// The foxglove numeric type of a PointCloud2 datatype.
fn numeric_type(ros: u8) -> NumericType {
    match ros {
        datatype::UINT8 => NumericType::Uint8,
        datatype::UINT16 => NumericType::Uint16,
        datatype::UINT32 => NumericType::Uint32,
        _ => NumericType::Float32,
    }
}

/// The sweep as a foxglove.PointCloud: the ROS 2 cloud's fields and bytes.
pub fn point_cloud(sweep: &Sweep, frame_id: &str) -> PointCloud {
    PointCloud {
        timestamp: Some(timestamp(sweep.start_us)),
        frame_id: frame_id.into(),
        pose: None,
        point_stride: POINT_STEP,
        fields: CLOUD_FIELDS
            .iter()
            .map(|&(name, offset, ros)| PackedElementField {
                name: name.into(),
                offset,
                r#type: numeric_type(ros) as i32,
            })
            .collect(),
        data: cloud_data(sweep).into(),
    }
}

/// A frame file as a foxglove.RawImage (colour files as luma), or why not.
fn raw_image(frame: &FrameFile, stamp: Timestamp, frame_id: &str) -> Result<RawImage, String> {
    let img = omni_vision::image_io::decode_gray(&frame.bytes, &frame.name).map_err(|e| e.to_string())?;
    let (encoding, data): (&str, Vec<u8>) = if img.bit_depth <= 8 {
        ("mono8", img.data.iter().map(|&v| v as u8).collect())
    } else {
        ("mono16", img.data.iter().flat_map(|v| v.to_le_bytes()).collect())
    };
    let bytes_per_px = if encoding == "mono8" { 1 } else { 2 };
    Ok(RawImage {
        timestamp: Some(stamp),
        frame_id: frame_id.into(),
        width: img.width,
        height: img.height,
        encoding: encoding.into(),
        step: img.width * bytes_per_px,
        data: data.into(),
    })
}

impl Sink for FoxgloveSink {
    fn name(&self) -> &str {
        "foxglove"
    }

    fn wants_frame(&self) -> bool {
        true
    }

    fn publish(&mut self, sweep: &Sweep, frame: Option<&FrameFile>) -> Result<(), String> {
        let stamp = timestamp(sweep.start_us);
        if let Some(json) = &self.opts.calibration {
            self.calibration.log(json.as_bytes());
        }
        if let Some(tf) = self.transform(stamp) {
            self.transforms.log(&tf);
        }
        if !sweep.points.is_empty() {
            self.points.log(&point_cloud(sweep, &self.opts.frame_id));
        }
        if let Some(f) = frame {
            let image = raw_image(f, timestamp(sweep.end_us), &self.opts.frame_id)?;
            self.image.log(&image);
        }
        Ok(())
    }
}
