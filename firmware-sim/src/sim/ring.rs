//! The sensor → ECU frame ring: a fixed number of stereo-frame slots allocated once at start-up.
//!
//! The sensor (DMA on a real ECU) writes a frame into the next free slot; the ECU takes the
//! oldest one. A frame that arrives while every slot is taken is dropped and counted (the ECU
//! never blocks the sensor). A slot is free again when the ECU starts processing its frame.
//! No allocation after [`FrameRing::new`].

/// Metadata of one frame in the ring.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SlotMeta {
    /// Sensor frame number (0-based, counts every sensor period).
    pub sensor_index: u32,
    /// Simulated arrival time (s): `sensor_index · period`.
    pub arrival_s: f64,
    /// Timestamp the sensor stamped on the frame (s); faults may disturb it.
    pub timestamp_s: f64,
    /// Faults injected into this frame ([`super::faults::FaultKind::bit`] flags).
    pub injected: u16,
}

/// One stereo frame slot: left and right luma with the bytes actually delivered.
#[derive(Debug)]
pub struct Slot {
    /// Left luma buffer (capacity: one full frame).
    pub left: Box<[u8]>,
    /// Right luma buffer.
    pub right: Box<[u8]>,
    /// Bytes of `left` the sensor delivered (a truncated transfer delivers fewer).
    pub left_len: usize,
    /// Bytes of `right` the sensor delivered.
    pub right_len: usize,
    /// Frame metadata.
    pub meta: SlotMeta,
}

impl Slot {
    /// The delivered left bytes.
    pub fn left(&self) -> &[u8] {
        &self.left[..self.left_len]
    }

    /// The delivered right bytes.
    pub fn right(&self) -> &[u8] {
        &self.right[..self.right_len]
    }
}

/// Bounded single-producer single-consumer ring of [`Slot`]s (one thread drives both ends in
/// the simulation; the discipline is the same as a DMA ring's).
#[derive(Debug)]
pub struct FrameRing {
    slots: Box<[Slot]>,
    head: usize,
    len: usize,
    high_water: usize,
    dropped: u32,
}

impl FrameRing {
    /// `capacity` slots (at least 1) of `frame_bytes` per image, zeroed.
    pub fn new(capacity: usize, frame_bytes: usize) -> Self {
        let slots = (0..capacity.max(1))
            .map(|_| Slot {
                left: vec![0u8; frame_bytes].into_boxed_slice(),
                right: vec![0u8; frame_bytes].into_boxed_slice(),
                left_len: 0,
                right_len: 0,
                meta: SlotMeta::default(),
            })
            .collect();
        Self { slots, head: 0, len: 0, high_water: 0, dropped: 0 }
    }

    /// Number of slots.
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No frame waiting.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Most frames that were ever waiting at once.
    pub fn high_water(&self) -> usize {
        self.high_water
    }

    /// Frames dropped because the ring was full.
    pub fn overflow_drops(&self) -> u32 {
        self.dropped
    }

    /// Bytes of frame storage (both images of every slot).
    pub fn storage_bytes(&self) -> usize {
        self.slots.iter().map(|s| s.left.len() + s.right.len()).sum()
    }

    /// Fills the next free slot with `fill` and queues it; when the ring is full the frame is
    /// dropped (counted) and `None` returned without calling `fill`.
    pub fn push_with<R>(&mut self, fill: impl FnOnce(&mut Slot) -> R) -> Option<R> {
        if self.len == self.slots.len() {
            self.dropped += 1;
            return None;
        }
        let i = (self.head + self.len) % self.slots.len();
        let r = fill(&mut self.slots[i]);
        self.len += 1;
        self.high_water = self.high_water.max(self.len);
        Some(r)
    }

    /// The oldest waiting frame.
    pub fn front(&self) -> Option<&Slot> {
        (self.len > 0).then(|| &self.slots[self.head])
    }

    /// Frees the oldest slot.
    pub fn pop(&mut self) {
        if self.len > 0 {
            self.head = (self.head + 1) % self.slots.len();
            self.len -= 1;
        }
    }

    /// Drops every waiting frame but the newest (catch-up after an overrun); returns how many.
    pub fn drop_stale(&mut self) -> usize {
        let n = self.len.saturating_sub(1);
        self.head = (self.head + n) % self.slots.len();
        self.len -= n;
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push(r: &mut FrameRing, k: u32) -> bool {
        r.push_with(|s| s.meta.sensor_index = k).is_some()
    }

    #[test]
    fn fifo_overflow_and_catch_up() {
        let mut r = FrameRing::new(3, 4);
        assert_eq!(r.storage_bytes(), 24);
        assert!(r.is_empty() && r.front().is_none());
        for k in 0..3 {
            assert!(push(&mut r, k));
        }
        assert!(!push(&mut r, 3), "full ring drops");
        assert_eq!((r.len(), r.overflow_drops(), r.high_water()), (3, 1, 3));
        assert_eq!(r.front().map(|s| s.meta.sensor_index), Some(0));
        r.pop();
        assert!(push(&mut r, 4));
        let order: Vec<u32> = core::iter::from_fn(|| {
            let k = r.front()?.meta.sensor_index;
            r.pop();
            Some(k)
        })
        .collect();
        assert_eq!(order, [1, 2, 4]);
        for k in 5..8 {
            push(&mut r, k);
        }
        assert_eq!(r.drop_stale(), 2);
        assert_eq!(r.front().map(|s| s.meta.sensor_index), Some(7));
        r.pop();
        r.pop();
        assert!(r.is_empty());
    }
}
