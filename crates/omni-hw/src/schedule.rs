//! The trigger schedule: which encoder positions fire, in which order, and with which lasers.
//!
//! The protocol fixes the order (see `docs/PROTOCOL.md`): in each revolution the configured
//! facets in increasing order, within each facet the configured angles in increasing order.
//! With ambient frames on, even revolutions (0, 2, …) fire with all lasers off and odd ones with
//! the configured lasers, so every laser frame has a laser-off frame of the same view taken one
//! revolution earlier at the same encoder position. Sequence number `seq` therefore determines the
//! expected trigger completely, which lets the host check every event and place lost ones.

use crate::message::{DeviceInfo, TriggerEvent};

/// Trigger angles within a facet as a person writes them (degrees).
#[derive(Debug, Clone, PartialEq)]
pub enum AngleSpec {
    /// `start:stop:step`, half-open: start, start+step, … < stop (degrees).
    Range { start_deg: f64, stop_deg: f64, step_deg: f64 },
    /// An explicit list (degrees).
    List(Vec<f64>),
}

impl AngleSpec {
    /// Parses `0:30:0.5` or `1.5,7,12.25`.
    pub fn parse(text: &str) -> Result<AngleSpec, String> {
        let num = |w: &str| -> Result<f64, String> {
            let v: f64 = w.trim().parse().map_err(|_| format!("angles: bad number {w:?}"))?;
            if v.is_finite() { Ok(v) } else { Err(format!("angles: {w:?} is not finite")) }
        };
        if text.contains(':') {
            let parts: Vec<&str> = text.split(':').collect();
            if parts.len() != 3 {
                return Err(format!("angles: expected start:stop:step, got {text:?}"));
            }
            let (start_deg, stop_deg, step_deg) = (num(parts[0])?, num(parts[1])?, num(parts[2])?);
            if !(step_deg > 0.0) || !(stop_deg > start_deg) {
                return Err(format!("angles: {text:?} needs step > 0 and stop > start"));
            }
            return Ok(AngleSpec::Range { start_deg, stop_deg, step_deg });
        }
        let list = text.split(',').map(num).collect::<Result<Vec<_>, _>>()?;
        Ok(AngleSpec::List(list))
    }

    /// The angles in degrees, in the order given.
    pub fn degrees(&self) -> Vec<f64> {
        match self {
            AngleSpec::List(v) => v.clone(),
            AngleSpec::Range { start_deg, stop_deg, step_deg } => {
                // Integer stepping avoids accumulating rounding; the 1e-9 keeps `stop` excluded.
                let n = ((stop_deg - start_deg) / step_deg - 1e-9).ceil().max(0.0) as u64;
                (0..n).map(|i| start_deg + i as f64 * step_deg).collect()
            }
        }
    }

    /// Encoder counts within a facet (rounded to the nearest count), strictly increasing.
    /// Errors name the angle outside the facet `[0, 360°/facets)` or two angles on one count.
    pub fn to_counts(&self, info: &DeviceInfo) -> Result<Vec<u32>, String> {
        let per_count = info.degrees_per_count();
        let facet_deg = 360.0 / info.facets as f64;
        let mut counts: Vec<u32> = Vec::new();
        let mut degs = self.degrees();
        degs.sort_by(f64::total_cmp);
        for d in degs {
            if !(d >= 0.0) || d >= facet_deg - 0.5 * per_count {
                return Err(format!("angle {d}° is outside the facet's range [0, {facet_deg}°)"));
            }
            let c = (d / per_count).round() as u32;
            if counts.last() == Some(&c) {
                return Err(format!("angle {d}° falls on the same encoder count as the previous angle"));
            }
            counts.push(c);
        }
        if counts.is_empty() {
            return Err("no trigger angles".into());
        }
        Ok(counts)
    }
}

/// The trigger expected for one sequence number.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpectedTrigger {
    pub facet: u32,
    /// Encoder count within the facet.
    pub count_in_facet: u32,
    /// Encoder count within the revolution.
    pub encoder: u32,
    pub revolution: u64,
    pub lasers: Vec<u32>,
}

/// What the controller was told to do.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    pub counts_per_rev: u32,
    pub facets_total: u32,
    /// Triggering facets, strictly increasing.
    pub facets: Vec<u32>,
    /// Trigger counts within a facet, strictly increasing.
    pub counts: Vec<u32>,
    /// Lasers on during laser frames.
    pub lasers: Vec<u32>,
    /// Even revolutions are laser-off (ambient) revolutions.
    pub ambient: bool,
}

impl Schedule {
    /// Checks the schedule against the controller's geometry.
    pub fn validate(&self) -> Result<(), String> {
        if self.facets_total == 0 || !self.counts_per_rev.is_multiple_of(self.facets_total) {
            return Err(format!(
                "{} counts per revolution do not divide into {} facets",
                self.counts_per_rev, self.facets_total
            ));
        }
        let per_facet = self.counts_per_rev / self.facets_total;
        let increasing = |v: &[u32]| v.windows(2).all(|w| w[0] < w[1]);
        if self.counts.is_empty() || !increasing(&self.counts) || self.counts.iter().any(|&c| c >= per_facet) {
            return Err(format!("trigger counts must be strictly increasing and below {per_facet}"));
        }
        if self.facets.is_empty() || !increasing(&self.facets) || self.facets.iter().any(|&f| f >= self.facets_total) {
            return Err(format!("facets must be strictly increasing and below {}", self.facets_total));
        }
        Ok(())
    }

    pub fn counts_per_facet(&self) -> u32 {
        self.counts_per_rev / self.facets_total
    }

    /// Triggers per revolution.
    pub fn per_revolution(&self) -> u64 {
        (self.facets.len() * self.counts.len()) as u64
    }

    /// The trigger with sequence number `seq`.
    pub fn expected(&self, seq: u64) -> ExpectedTrigger {
        let per_rev = self.per_revolution().max(1);
        let revolution = seq / per_rev;
        let i = (seq % per_rev) as usize;
        let facet = self.facets[i / self.counts.len()];
        let count_in_facet = self.counts[i % self.counts.len()];
        let lasers = if self.ambient && revolution.is_multiple_of(2) { vec![] } else { self.lasers.clone() };
        ExpectedTrigger {
            facet,
            count_in_facet,
            encoder: facet * self.counts_per_facet() + count_in_facet,
            revolution,
            lasers,
        }
    }

    /// Absolute encoder position of trigger `seq` since the start of the run (counts).
    pub fn position(&self, seq: u64) -> u64 {
        let e = self.expected(seq);
        e.revolution * self.counts_per_rev as u64 + e.encoder as u64
    }

    /// Whether an event is exactly the trigger its sequence number promises.
    pub fn check(&self, ev: &TriggerEvent) -> Result<(), String> {
        let e = self.expected(ev.seq);
        if (ev.encoder, ev.facet, ev.revolution, &ev.lasers) != (e.encoder, e.facet, e.revolution, &e.lasers) {
            return Err(format!(
                "trigger seq {} reports enc={} facet={} rev={} but the schedule expects enc={} facet={} rev={}{}",
                ev.seq,
                ev.encoder,
                ev.facet,
                ev.revolution,
                e.encoder,
                e.facet,
                e.revolution,
                if ev.lasers != e.lasers { " (and other lasers)" } else { "" }
            ));
        }
        Ok(())
    }

    /// Mirror angle within the facet of a trigger at encoder count `encoder` (degrees).
    pub fn alpha_deg(&self, encoder: u32) -> f64 {
        (encoder % self.counts_per_facet()) as f64 * 360.0 / self.counts_per_rev as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> DeviceInfo {
        DeviceInfo {
            protocol: 1,
            firmware: "t".into(),
            counts_per_rev: 36000,
            facets: 12,
            lasers: 2,
            max_rate_hz: 100.0,
        }
    }

    #[test]
    fn ranges_are_half_open_and_exact_on_the_count_grid() {
        let spec = AngleSpec::parse("0:30:0.5").unwrap();
        let counts = spec.to_counts(&info()).unwrap();
        assert_eq!(counts.len(), 60);
        assert_eq!(counts[0], 0);
        assert_eq!(counts[59], 2950);
        let spec = AngleSpec::parse("1.5, 7,12.25").unwrap();
        assert_eq!(spec.to_counts(&info()).unwrap(), vec![150, 700, 1225]);
    }

    #[test]
    fn bad_angles_are_refused_with_the_angle_named() {
        assert!(AngleSpec::parse("0:30").is_err());
        assert!(AngleSpec::parse("0:30:0").is_err());
        assert!(AngleSpec::parse("1,NaN").is_err());
        let e = AngleSpec::parse("10,31").unwrap().to_counts(&info()).unwrap_err();
        assert!(e.contains("31"), "{e}");
        let e = AngleSpec::parse("10,10.001").unwrap().to_counts(&info()).unwrap_err();
        assert!(e.contains("same encoder count"), "{e}");
    }

    #[test]
    fn sequence_numbers_walk_facets_then_angles_then_revolutions() {
        let s = Schedule {
            counts_per_rev: 36000,
            facets_total: 12,
            facets: vec![2, 5],
            counts: vec![100, 200, 300],
            lasers: vec![0, 1],
            ambient: true,
        };
        s.validate().unwrap();
        let e = s.expected(4);
        assert_eq!((e.facet, e.count_in_facet, e.encoder, e.revolution), (5, 200, 5 * 3000 + 200, 0));
        assert!(e.lasers.is_empty(), "revolution 0 is a laser-off revolution");
        let e = s.expected(6);
        assert_eq!((e.facet, e.count_in_facet, e.revolution, e.lasers.clone()), (2, 100, 1, vec![0, 1]));
        assert_eq!(s.position(6), 36000 + 6100);
        assert!((s.alpha_deg(e.encoder) - 1.0).abs() < 1e-12);
        let mut ev = TriggerEvent { seq: 6, encoder: 6100, facet: 2, revolution: 1, t_us: 0, lasers: vec![0, 1] };
        assert!(s.check(&ev).is_ok());
        ev.encoder = 6200;
        assert!(s.check(&ev).is_err());
    }
}
