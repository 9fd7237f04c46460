//! Camera frame identifiers: the GigE Vision block id and the host's record of the software
//! triggers it fired. Pure bookkeeping, no camera library, so it is tested without one.

/// Turns the camera's wrapping frame counter into a monotonic index.
///
/// GigE Vision (GVSP 1.x) numbers frames with a 16-bit block id that skips 0 (reserved): after
/// 65535 comes 1. USB3 Vision and GVSP 2 extended ids are 64-bit and never wrap in practice;
/// they pass through unchanged as long as they stay above the 16-bit range. The index of the
/// first frame seen is 0; a frame lost on the way (or dropped as incomplete and never seen)
/// leaves a gap, which [`BlockIdUnwrapper::push`] reports.
#[derive(Debug, Clone, Default)]
pub struct BlockIdUnwrapper {
    /// The previous raw id and its index.
    last: Option<(u64, u64)>,
}

/// Ids per turn of the 16-bit counter (0 is skipped).
const BLOCK_IDS_PER_TURN: u64 = 65535;

impl BlockIdUnwrapper {
    /// The index of the frame with raw id `raw`, and how many frames were skipped since the
    /// previous one. A raw id that does not advance (a repeated or older frame) returns `None`.
    pub fn push(&mut self, raw: u64) -> Option<(u64, u64)> {
        let Some((last_raw, last_index)) = self.last else {
            self.last = Some((raw, 0));
            return Some((0, 0));
        };
        let step = forward_distance(last_raw, raw)?;
        let index = last_index + step;
        self.last = Some((raw, index));
        Some((index, step - 1))
    }

    /// The index of `raw` if it is the latest id or one before it (a buffer handed back late).
    pub fn index_of(&self, raw: u64) -> Option<u64> {
        let (last_raw, last_index) = self.last?;
        if raw == last_raw {
            return Some(last_index);
        }
        forward_distance(raw, last_raw).and_then(|d| last_index.checked_sub(d))
    }
}

/// Counts every broken camera frame once. A frame whose block id the stream skipped is lost
/// until an incomplete buffer for it turns up: Aravis hands incomplete buffers back when their
/// timeout expires, often after later frames. An incomplete buffer with no id (0: none of its
/// leader packets arrived) stands for one skipped frame, before or after the gap is seen.
#[derive(Debug, Clone, Default)]
pub struct LossCount {
    /// Indices skipped and not yet accounted for by an incomplete buffer.
    gaps: std::collections::BTreeSet<u64>,
    /// Incomplete buffers without an id that no gap has taken up yet.
    unnamed: u64,
    pub lost: u64,
    pub incomplete: u64,
}

impl LossCount {
    /// Frames `indices` were skipped by the block ids.
    pub fn skipped(&mut self, indices: std::ops::Range<u64>) {
        for index in indices {
            if self.unnamed > 0 {
                self.unnamed -= 1;
            } else {
                self.gaps.insert(index);
                self.lost += 1;
            }
        }
    }

    /// An incomplete buffer of the newest frame, `index`.
    pub fn incomplete_named(&mut self, index: u64) {
        self.incomplete += 1;
        if self.gaps.remove(&index) {
            self.lost -= 1;
        }
    }

    /// An incomplete buffer of an older frame (`None`: older than any index kept). It counts
    /// only if that frame was skipped: otherwise the frame arrived whole and this is a second,
    /// partial copy of it.
    pub fn incomplete_late(&mut self, index: Option<u64>) {
        if index.is_some_and(|i| self.gaps.remove(&i)) {
            self.lost -= 1;
            self.incomplete += 1;
        }
    }

    /// An incomplete buffer that carries no block id.
    pub fn incomplete_unnamed(&mut self) {
        self.incomplete += 1;
        if self.gaps.pop_first().is_some() {
            self.lost -= 1;
        } else {
            self.unnamed += 1;
        }
    }
}

/// How far `raw` is after `last` (≥ 1), or `None` if it is not after it. 16-bit ids move
/// forward modulo 65535 on the ring 1..=65535; a jump of more than half the ring is taken as
/// going backwards (a stale or duplicated frame), as GigE Vision receivers do.
fn forward_distance(last: u64, raw: u64) -> Option<u64> {
    let is_16_bit = |v: u64| (1..=BLOCK_IDS_PER_TURN).contains(&v);
    if is_16_bit(last) && is_16_bit(raw) {
        let d = (raw + BLOCK_IDS_PER_TURN - last) % BLOCK_IDS_PER_TURN;
        (d != 0 && d < BLOCK_IDS_PER_TURN / 2).then_some(d)
    } else {
        (raw > last).then(|| raw - last)
    }
}

/// The software triggers the host fired, in order: which controller trigger each was for and
/// when (host clock). A frame answers the latest trigger fired before its exposure, so its
/// trigger is known from what the host did rather than from the order frames arrive in.
#[derive(Debug, Clone, Default)]
pub struct TriggerLedger {
    /// (trigger seq, host time µs the software trigger was sent), oldest first.
    fired: std::collections::VecDeque<(u64, i64)>,
}

/// Entries kept: far more than can be in flight, so memory stays bounded in long scans.
const LEDGER_CAPACITY: usize = 4096;

impl TriggerLedger {
    /// Trigger `seq`'s software trigger is about to be sent at host time `sent_us`.
    pub fn record(&mut self, seq: u64, sent_us: i64) {
        if self.fired.len() == LEDGER_CAPACITY {
            self.fired.pop_front();
        }
        self.fired.push_back((seq, sent_us));
    }

    /// The trigger a frame exposed at host time `exposure_us` answers: the latest one sent at or
    /// before it. Earlier entries are dropped (frames come in exposure order).
    pub fn answer(&mut self, exposure_us: i64) -> Option<u64> {
        while self.fired.len() > 1 && self.fired[1].1 <= exposure_us {
            self.fired.pop_front();
        }
        match self.fired.front() {
            Some(&(seq, sent)) if sent <= exposure_us => {
                self.fired.pop_front();
                Some(seq)
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_16_bit_block_id_wraps_from_65535_to_1() {
        let mut u = BlockIdUnwrapper::default();
        let ids = [65400u64, 65401, 65535, 1, 2, 3];
        let got: Vec<(u64, u64)> = ids.iter().map(|&r| u.push(r).unwrap()).collect();
        // 65401 → 65535 is 134 frames; 65535 → 1 is one frame (0 is skipped).
        assert_eq!(got, vec![(0, 0), (1, 0), (135, 133), (136, 0), (137, 0), (138, 0)]);
    }

    #[test]
    fn gaps_across_the_wrap_are_counted_and_old_ids_refused() {
        let mut u = BlockIdUnwrapper::default();
        assert_eq!(u.push(65534), Some((0, 0)));
        // 65535 and 1 lost.
        assert_eq!(u.push(2), Some((3, 2)));
        assert_eq!(u.push(2), None, "a repeated id is not a new frame");
        assert_eq!(u.push(65535), None, "an id from before the wrap is stale");
        assert_eq!(u.push(3), Some((4, 0)));
    }

    /// Incomplete buffers handed back after later frames, with or without their id, turn a
    /// frame counted lost into one counted incomplete: each broken frame is counted once.
    #[test]
    fn a_late_incomplete_buffer_is_not_counted_twice() {
        let mut ids = BlockIdUnwrapper::default();
        let mut count = LossCount::default();
        for raw in [65400, 65401] {
            ids.push(raw);
        }
        let (index, skipped) = ids.push(65404).unwrap();
        count.skipped(index - skipped..index);
        assert_eq!((count.lost, count.incomplete), (2, 0));
        count.incomplete_late(ids.index_of(65402));
        assert_eq!((count.lost, count.incomplete), (1, 1));
        // A partial copy of a frame that arrived whole is no broken frame.
        count.incomplete_late(ids.index_of(65401));
        assert_eq!((count.lost, count.incomplete), (1, 1));
        count.incomplete_unnamed();
        assert_eq!((count.lost, count.incomplete), (0, 2));
        // An unnamed one before its gap is seen.
        count.incomplete_unnamed();
        let (index, skipped) = ids.push(65406).unwrap();
        count.skipped(index - skipped..index);
        assert_eq!((count.lost, count.incomplete), (0, 3));
        assert_eq!(ids.index_of(65406), Some(6));
        assert_eq!(ids.index_of(65410), None);
    }

    #[test]
    fn wide_ids_pass_through() {
        let mut u = BlockIdUnwrapper::default();
        assert_eq!(u.push(1 << 40), Some((0, 0)));
        assert_eq!(u.push((1 << 40) + 3), Some((3, 2)));
        assert_eq!(u.push(1 << 40), None);
    }

    #[test]
    fn a_frame_answers_the_latest_trigger_sent_before_its_exposure() {
        let mut l = TriggerLedger::default();
        assert_eq!(l.answer(5), None, "nothing fired yet");
        l.record(7, 100);
        l.record(8, 200);
        l.record(10, 300);
        assert_eq!(l.answer(150), Some(7));
        // Trigger 8 never produced a frame: the next frame (after 300) answers 10, not 8.
        assert_eq!(l.answer(320), Some(10));
        assert_eq!(l.answer(330), None, "each trigger is answered once");
    }
}
