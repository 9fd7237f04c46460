//! Sweeps from a stream of measured frames.
//!
//! A sweep is one facet's pass of the lasers: every frame of one `(revolution, facet)` in turn,
//! a full 360° × 60° scan. Frames arrive in trigger order, so a sweep ends with its last
//! expected frame (when the number of trigger angles per facet is known), when a frame of
//! another sweep arrives (then it is complete if no trigger sequence number is missing inside
//! it), when the input ends, or when no frame has arrived for a while (then it is published
//! incomplete, never held forever).

use omni_formats::stream::Frame;

/// One point of a sweep, in the sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepPoint {
    /// Position (mm, sensor frame, or the sweep's end pose when deskewed).
    pub xyz_mm: [f64; 3],
    /// The stripe's peak intensity at the point (the frame's grey levels).
    pub intensity: f32,
    /// Time of the point's frame after the sweep's first frame (ns).
    pub t_ns: u32,
    /// The frame's trigger sequence number.
    pub frame: u32,
    /// The frame's index within the sweep: each frame is one 360° ring of points.
    pub ring: u16,
    /// Mirror angle of the point's frame within the facet (degrees).
    pub alpha_deg: f32,
    /// Laser whose light plane gave the point.
    pub laser: u8,
}

/// A finished sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    pub revolution: u64,
    pub facet: u32,
    /// Timestamp of the sweep's first frame (µs, the stream's clock): the message stamp.
    pub start_us: u64,
    /// Timestamp of its last frame (µs).
    pub end_us: u64,
    /// Frames it holds (laser-off frames included).
    pub frames: u32,
    /// Frames known to be missing inside it (gaps in the trigger sequence).
    pub frames_missing: u32,
    /// Ended by the next sweep's first frame with no frame missing inside it.
    pub complete: bool,
    /// Image path (as the stream gives it) of its last frame with a laser on.
    pub last_frame_path: Option<String>,
    pub points: Vec<SweepPoint>,
}

/// Why a sweep was closed, which decides whether it can be complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Close {
    /// The next sweep began.
    NextSweep,
    /// The input ended or stopped arriving: the sweep's last frames may never come.
    Cut,
}

/// Groups frames into sweeps.
#[derive(Debug, Default)]
pub struct SweepAssembler {
    /// Frames per sweep (trigger angles per facet), if known: the sweep closes on its last.
    expected_frames: Option<u32>,
    open: Option<Sweep>,
    last_seq: Option<u64>,
    /// Times (µs) of the frames of the open sweep are taken relative to its first.
    open_frames: u16,
}

impl SweepAssembler {
    /// `expected_frames`: trigger angles per facet, if known (a sweep then closes complete on
    /// its last frame instead of waiting for the next sweep's first).
    pub fn new(expected_frames: Option<u32>) -> Self {
        SweepAssembler { expected_frames: expected_frames.filter(|&n| n > 0), ..Self::default() }
    }

    /// Adds a measured frame (its `points` from omni-triangulate, `stripe` for the intensity);
    /// returns the sweeps it closed (the previous one, and its own if it was the last expected),
    /// oldest first. A frame without timestamp counts as time 0.
    pub fn push(&mut self, frame: &Frame) -> Vec<Sweep> {
        let key = (frame.revolution, frame.facet);
        let mut closed = Vec::new();
        if self.open.as_ref().is_some_and(|s| (s.revolution, s.facet) != key) {
            closed.extend(self.close(Close::NextSweep));
        }
        let stamp = frame.timestamp_us.unwrap_or(0);
        let missing = match self.last_seq {
            Some(last) if frame.seq > last + 1 && self.open.is_some() => (frame.seq - last - 1) as u32,
            _ => 0,
        };
        self.last_seq = Some(frame.seq);
        let sweep = self.open.get_or_insert_with(|| Sweep {
            revolution: frame.revolution,
            facet: frame.facet,
            start_us: stamp,
            end_us: stamp,
            frames: 0,
            frames_missing: 0,
            complete: false,
            last_frame_path: None,
            points: Vec::new(),
        });
        sweep.frames_missing += missing;
        sweep.frames += 1;
        sweep.end_us = sweep.end_us.max(stamp);
        if !frame.lasers.is_empty() {
            sweep.last_frame_path = Some(frame.path.clone());
        }
        let ring = self.open_frames;
        self.open_frames = self.open_frames.saturating_add(1);
        append_points(sweep, frame, ring, stamp);
        if self.expected_frames.is_some_and(|n| sweep.frames + sweep.frames_missing >= n) {
            closed.extend(self.close(Close::NextSweep));
        }
        closed
    }

    /// Closes the open sweep (the input ended or stalled).
    pub fn flush(&mut self) -> Option<Sweep> {
        self.close(Close::Cut)
    }

    /// Whether a sweep is open.
    pub fn is_open(&self) -> bool {
        self.open.is_some()
    }

    fn close(&mut self, why: Close) -> Option<Sweep> {
        let mut sweep = self.open.take()?;
        self.open_frames = 0;
        let all_frames = self.expected_frames.is_none_or(|n| sweep.frames >= n);
        sweep.complete = why == Close::NextSweep && sweep.frames_missing == 0 && all_frames;
        Some(sweep)
    }
}

fn append_points(sweep: &mut Sweep, frame: &Frame, ring: u16, stamp_us: u64) {
    let Some(points) = &frame.points else { return };
    let stripe = frame.stripe.as_deref().unwrap_or(&[]);
    // A frame is well under 4.29 s after its sweep's start; clamp rather than wrap if not.
    let t_ns = (stamp_us.saturating_sub(sweep.start_us).saturating_mul(1000)).min(u64::from(u32::MAX)) as u32;
    sweep.points.extend(points.iter().map(|p| SweepPoint {
        xyz_mm: p.xyz,
        intensity: stripe.get(p.stripe_index as usize).map_or(0.0, |s| s.intensity as f32),
        t_ns,
        frame: frame.seq as u32,
        ring,
        alpha_deg: frame.alpha_deg as f32,
        laser: p.laser.min(255) as u8,
    }));
}

#[cfg(test)]
mod tests {
    use super::*;
    use omni_formats::stream::{Point, StripePoint};

    fn frame(seq: u64, revolution: u64, facet: u32, t_us: u64, n: usize) -> Frame {
        let mut f = Frame::new(seq, format!("{seq}.png"), 0.5 * seq as f64, facet);
        f.revolution = revolution;
        f.timestamp_us = Some(t_us);
        f.stripe = Some(
            (0..n)
                .map(|i| StripePoint { u: i as f64, v: 0.0, intensity: 100.0 + i as f64, width: 2.0, quality: 0 })
                .collect(),
        );
        f.points = Some(
            (0..n)
                .map(|i| Point { xyz: [i as f64, 1.0, 2.0], laser: (i % 2) as u32, range: 3.0, stripe_index: i as u32 })
                .collect(),
        );
        f
    }

    #[test]
    fn a_sweep_closes_when_the_next_facet_begins_and_times_are_relative_to_its_first_frame() {
        let mut a = SweepAssembler::new(None);
        assert!(a.push(&frame(0, 0, 0, 1_000, 3)).is_empty());
        assert!(a.push(&frame(1, 0, 0, 1_250, 2)).is_empty());
        let s = a.push(&frame(2, 0, 1, 1_500, 1)).pop().expect("facet 1 closes facet 0");
        assert!(s.complete);
        assert_eq!((s.frames, s.start_us, s.end_us, s.points.len()), (2, 1_000, 1_250, 5));
        assert_eq!(s.points[3].t_ns, 250_000);
        assert_eq!((s.points[3].ring, s.points[3].frame, s.points[4].laser), (1, 1, 1));
        assert_eq!(s.points[2].intensity, 102.0);
        let last = a.flush().expect("the open sweep");
        assert!(!last.complete, "cut by the end of input");
        assert!(a.flush().is_none());
    }

    #[test]
    fn a_gap_in_the_trigger_sequence_marks_the_sweep_incomplete() {
        let mut a = SweepAssembler::new(None);
        a.push(&frame(10, 3, 5, 0, 1));
        a.push(&frame(13, 3, 5, 750, 1));
        let s = a.push(&frame(14, 3, 6, 1_000, 1)).pop().unwrap();
        assert_eq!((s.frames, s.frames_missing, s.complete), (2, 2, false));
    }

    #[test]
    fn with_known_angles_a_sweep_closes_on_its_last_frame() {
        let mut a = SweepAssembler::new(Some(3));
        assert!(a.push(&frame(0, 0, 0, 0, 1)).is_empty());
        assert!(a.push(&frame(1, 0, 0, 250, 1)).is_empty());
        let s = a.push(&frame(2, 0, 0, 500, 1));
        assert_eq!(s.len(), 1);
        assert!(s[0].complete && !a.is_open());
        // Frame 4 lost: frame 5 is still the sweep's last, which closes incomplete.
        a.push(&frame(3, 0, 1, 750, 1));
        let s = a.push(&frame(5, 0, 1, 1_250, 1));
        assert_eq!((s.len(), s[0].frames, s[0].frames_missing, s[0].complete), (1, 2, 1, false));
        // A sweep whose last frames never come is closed by the next one's first.
        a.push(&frame(6, 0, 2, 1_500, 1));
        let s = a.push(&frame(9, 1, 0, 2_250, 1));
        assert_eq!((s.len(), s[0].facet, s[0].frames, s[0].complete), (1, 2, 1, false));
        let s = a.flush().unwrap();
        assert_eq!((s.revolution, s.facet, s.frames, s.complete), (1, 0, 1, false));
    }
}
