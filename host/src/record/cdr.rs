//! Little-endian CDR (XCDR1, as ROS 2's DDS middlewares put messages on the wire and rosbag2 stores
//! them): a 4-byte encapsulation header (`00 01`: CDR_LE, then two option bytes), then each field
//! in order, every primitive aligned to its own size counted from the end of the header; strings as
//! a `uint32` length that counts the terminating NUL, the bytes and the NUL; sequences as a
//! `uint32` element count and the elements; fixed arrays as their elements only.

/// The encapsulation header of little-endian plain CDR.
pub const ENCAPSULATION_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A CDR message being written.
#[derive(Clone, Debug)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    /// An empty message: the encapsulation header only.
    pub fn new() -> Self {
        let mut buf = Vec::with_capacity(256);
        buf.extend_from_slice(&ENCAPSULATION_LE);
        Self { buf }
    }

    /// The serialised message.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }

    /// Pads with zeros to a multiple of `n` bytes after the header.
    fn align(&mut self, n: usize) {
        let offset = self.buf.len().saturating_sub(ENCAPSULATION_LE.len());
        let rem = offset.checked_rem(n).unwrap_or(0);
        if rem != 0 {
            let len = self.buf.len().saturating_add(n.saturating_sub(rem));
            self.buf.resize(len, 0);
        }
    }

    /// An `uint8` (also `byte`, `char`, `bool` as 0/1).
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// An `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A sequence's element count (a length beyond `u32` is written as `u32::MAX`: no message of
    /// this crate comes near it).
    pub fn len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    /// A `string`: length with the NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) {
        self.len(s.len().saturating_add(1));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A fixed array of `float64` (no count).
    pub fn f64_array(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }

    /// A `float64[]` sequence.
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.len(v.len());
        self.f64_array(v);
    }

    /// A `string[]` sequence.
    pub fn string_seq(&mut self, v: &[String]) {
        self.len(v.len());
        for s in v {
            self.string(s);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Alignment counts from the end of the header: a byte, then an `int32` three bytes later,
    /// then a `float64` at offset 8 (no padding), then after a 1-byte string (length 2) at 16..22 a
    /// `float64` padded to 24.
    #[test]
    fn alignment_is_counted_from_the_end_of_the_header() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.i32(-2);
        w.f64(1.0);
        w.string("a");
        w.f64(-0.5);
        let got = w.finish();
        let want: Vec<u8> = [
            &ENCAPSULATION_LE[..],
            &[7, 0, 0, 0],
            &(-2i32).to_le_bytes(),
            &1.0f64.to_le_bytes(),
            &[2, 0, 0, 0, b'a', 0, 0, 0],
            &(-0.5f64).to_le_bytes(),
        ]
        .concat();
        assert_eq!(got, want);
    }

    #[test]
    fn an_empty_string_is_a_length_of_one_and_a_nul() {
        let mut w = CdrWriter::new();
        w.string("");
        assert_eq!(w.finish(), [0, 1, 0, 0, 1, 0, 0, 0, 0]);
    }
}
