//! A simulated serial line, one direction: bytes leave back to back at the line's rate and arrive
//! after their own transmission time and a fixed latency (the USB host stack's, or none for a bare
//! UART); each byte may have a bit flipped on the way.
//!
//! ```text
//!  sender   ── write(frame) ──▶ [ b0 | b1 | b2 | … ]          one byte per 10 bit times (8N1)
//!  line           ├ byte_s ┤├ byte_s ┤├ byte_s ┤
//!  receiver                  + latency ▶ b0   ▶ b1   ▶ b2      each at its own arrival time
//! ```
//!
//! Every byte carries a tag (the index of the frame it belongs to), so the simulator can tell
//! which frame a byte the board consumed came from.

use std::collections::VecDeque;

use crate::rng::Rng;

/// A byte on the line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InFlight {
    /// Arrival time at the receiver, s.
    pub at: f64,
    /// The byte as it arrives.
    pub byte: u8,
    /// The sender's tag.
    pub tag: usize,
    /// A bit of it was flipped on the line.
    pub flipped: bool,
}

/// One direction of a serial line.
#[derive(Clone, Debug)]
pub struct Wire {
    byte_s: f64,
    latency_s: f64,
    bit_error_rate: f64,
    free_at: f64,
    line: VecDeque<InFlight>,
}

impl Wire {
    /// A line at `baud` (8N1: ten bit times per byte) with `latency_ms` after each byte and a
    /// probability `bit_error_rate` per bit of a flipped bit.
    pub fn new(baud: f64, latency_ms: f64, bit_error_rate: f64) -> Self {
        Self {
            byte_s: 10.0 / baud,
            latency_s: latency_ms * 1e-3,
            bit_error_rate,
            free_at: 0.0,
            line: VecDeque::new(),
        }
    }

    /// Time one byte occupies the line, s.
    pub fn byte_s(&self) -> f64 {
        self.byte_s
    }

    /// True if a byte written at `t` would start at once (nothing still being sent).
    pub fn idle(&self, t: f64) -> bool {
        self.free_at <= t
    }

    /// True if the line is free before `t`: a byte written now would start before `t`.
    pub fn idle_before(&self, t: f64) -> bool {
        self.free_at < t
    }

    /// Writes `bytes` at `t`, behind whatever is still being sent. Returns how many had a bit
    /// flipped (with eight data bits, a byte has one flipped with probability 8 · bit_error_rate).
    pub fn write(&mut self, t: f64, bytes: &[u8], tag: usize, rng: &mut Rng) -> usize {
        let mut flips = 0;
        for &b in bytes {
            let start = self.free_at.max(t);
            self.free_at = start + self.byte_s;
            let flipped = rng.chance(8.0 * self.bit_error_rate);
            let byte = if flipped {
                flips += 1;
                b ^ (1 << rng.below(8))
            } else {
                b
            };
            self.line.push_back(InFlight {
                at: self.free_at + self.latency_s,
                byte,
                tag,
                flipped,
            });
        }
        flips
    }

    /// The next byte that has arrived by `t`, in order.
    pub fn arrived(&mut self, t: f64) -> Option<InFlight> {
        if self.line.front().is_some_and(|b| b.at <= t) {
            self.line.pop_front()
        } else {
            None
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn bytes_arrive_back_to_back_after_the_latency() {
        let mut rng = Rng::new(1);
        let mut w = Wire::new(100_000.0, 1.0, 0.0);
        assert_eq!(w.write(0.0, &[1, 2, 3], 7, &mut rng), 0);
        // 100 µs per byte: the third byte ends at 300 µs and arrives 1 ms later.
        assert!(w.arrived(1.099e-3).is_none());
        let b = w.arrived(1.1e-3 + 1e-12).unwrap();
        assert_eq!((b.byte, b.tag), (1, 7));
        assert!(!w.idle(0.25e-3) && w.idle(0.3e-3 + 1e-12));
        assert!(w.arrived(1.25e-3).is_some() && w.arrived(1.25e-3).is_none());
        assert_eq!(w.arrived(2.0).unwrap().byte, 3);
    }

    #[test]
    fn a_flipped_byte_differs_in_one_bit() {
        let mut rng = Rng::new(3);
        let mut w = Wire::new(1e6, 0.0, 1.0 / 8.0);
        assert_eq!(w.write(0.0, &[0x55; 64], 0, &mut rng), 64);
        while let Some(b) = w.arrived(1.0) {
            assert!(b.flipped && (b.byte ^ 0x55).count_ones() == 1);
        }
    }
}
