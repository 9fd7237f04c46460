//! The emulator's virtual camera images: rendered through `omni_simulator`, or blank.

use omni_hw::emulator::{FrameRenderer, Shot};
use omni_simulator::{RenderOptions, Scene, Sensor, render_ambient_frame, render_laser_frame};
use std::time::Instant;

/// Renders each shot of the simulated sensor looking at a scene (8-bit PNG).
pub struct SimRenderer {
    pub sensor: Sensor,
    pub scene: Scene,
    pub options: RenderOptions,
}

impl FrameRenderer for SimRenderer {
    fn render(&mut self, shot: &Shot) -> Result<Vec<u8>, String> {
        let image = if shot.lasers.is_empty() {
            render_ambient_frame(&self.sensor, &self.scene, &self.options)
        } else {
            render_laser_frame(&self.sensor, &self.scene, shot.alpha_rad, shot.facet, &shot.lasers, &self.options).image
        };
        image.to_png_bytes()
    }
}

/// Seconds the slowest of a few representative frames takes to render (the emulator limits its
/// trigger rate to what the camera can do).
pub fn measure_frame_time(renderer: &mut dyn FrameRenderer, lasers: &[u32], facets: u32) -> Result<f64, String> {
    let facet_deg = 360.0 / facets.max(1) as f64;
    let mut worst = 0.0_f64;
    for alpha_deg in [0.25 * facet_deg, 0.5 * facet_deg, 0.75 * facet_deg] {
        let shot = Shot {
            trigger_seq: 0,
            alpha_rad: alpha_deg.to_radians(),
            facet: 0,
            lasers: lasers.to_vec(),
            exposure: std::time::SystemTime::now(),
        };
        let t = Instant::now();
        renderer.render(&shot)?;
        worst = worst.max(t.elapsed().as_secs_f64());
    }
    Ok(worst)
}
