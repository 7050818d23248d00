//! A minimal protobuf wire-format reader and writer for the fixed messages of [`crate::amr`]: no alloc, no panic.
//!
//! Encoding rules (protobuf "Encoding" guide): a field is a key varint `(field_number << 3) | wire_type`
//! then its value; wire type 0 = varint, 1 = 8 bytes (I64), 2 = length-delimited (LEN), 5 = 4 bytes (I32);
//! 3 and 4 are the deprecated groups. proto3 scalars with implicit presence are not written when they
//! hold the default (zero) value; a reader sees a missing field as zero, skips unknown fields by wire
//! type, and keeps the last value of a repeated scalar field ("last one wins").

/// Wire type 0: base-128 varint.
pub(crate) const WT_VARINT: u8 = 0;
/// Wire type 1: eight little-endian bytes.
pub(crate) const WT_I64: u8 = 1;
/// Wire type 2: varint length then that many bytes.
pub(crate) const WT_LEN: u8 = 2;
/// Wire type 5: four little-endian bytes.
pub(crate) const WT_I32: u8 = 5;

/// The largest field number protobuf allows (2²⁹ − 1).
pub(crate) const MAX_FIELD: u32 = (1 << 29) - 1;

/// The payload is not valid protobuf for this message (truncated, overlong, bad key, wrong wire type, out of range).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct DecodeError;

/// Bytes a varint of `v` takes (1 ..= 10).
pub(crate) const fn varint_len(v: u64) -> usize {
    let mut n: usize = 1;
    let mut rest = v >> 7;
    while rest != 0 {
        n = n.saturating_add(1);
        rest >>= 7;
    }
    n
}

/// Bytes the key of field `field` takes.
pub(crate) const fn key_len(field: u32) -> usize {
    varint_len((field as u64) << 3)
}

/// Largest encoding of a `uint32` field: key + 5-byte varint.
pub(crate) const fn max_uint32(field: u32) -> usize {
    key_len(field).saturating_add(varint_len(u32::MAX as u64))
}

/// Largest encoding of a `sint32` field: key + 5-byte zigzag varint.
pub(crate) const fn max_sint32(field: u32) -> usize {
    key_len(field).saturating_add(varint_len(u32::MAX as u64))
}

/// Encoding of a `fixed32`/`float` field: key + 4 bytes.
pub(crate) const fn max_fixed32(field: u32) -> usize {
    key_len(field).saturating_add(4)
}

/// Largest encoding of a `uint32` field whose value never exceeds `max`.
pub(crate) const fn max_uint32_upto(field: u32, max: u32) -> usize {
    key_len(field).saturating_add(varint_len(max as u64))
}

/// ZigZag encoding of a `sint32` (0 → 0, −1 → 1, 1 → 2, …).
pub(crate) const fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

/// Inverse of [`zigzag`].
pub(crate) const fn unzigzag(v: u32) -> i32 {
    ((v >> 1) ^ 0u32.wrapping_sub(v & 1)) as i32
}

/// Writes fields into a fixed buffer; never panics. Bytes that do not fit are dropped (the message
/// size bounds in [`crate::amr`] are const-asserted, so this never happens there; the round-trip
/// harnesses check it).
pub(crate) struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    /// A writer at the start of `buf`.
    pub(crate) fn new(buf: &'a mut [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    /// Bytes written so far.
    pub(crate) fn len(&self) -> usize {
        self.pos
    }

    fn byte(&mut self, b: u8) {
        if let Some(slot) = self.buf.get_mut(self.pos) {
            *slot = b;
            self.pos = self.pos.saturating_add(1);
        }
    }

    fn varint(&mut self, v: u64) {
        let mut rest = v;
        loop {
            let low = (rest & 0x7F) as u8;
            rest >>= 7;
            if rest == 0 {
                self.byte(low);
                return;
            }
            self.byte(low | 0x80);
        }
    }

    fn key(&mut self, field: u32, wire_type: u8) {
        self.varint((u64::from(field) << 3) | u64::from(wire_type));
    }

    /// A `uint32` field, omitted when zero.
    pub(crate) fn uint32(&mut self, field: u32, v: u32) {
        if v != 0 {
            self.key(field, WT_VARINT);
            self.varint(u64::from(v));
        }
    }

    /// A `sint32` field, omitted when zero.
    pub(crate) fn sint32(&mut self, field: u32, v: i32) {
        if v != 0 {
            self.key(field, WT_VARINT);
            self.varint(u64::from(zigzag(v)));
        }
    }

    /// A `fixed32` field, omitted when zero.
    pub(crate) fn fixed32(&mut self, field: u32, v: u32) {
        if v != 0 {
            self.key(field, WT_I32);
            for b in v.to_le_bytes() {
                self.byte(b);
            }
        }
    }

    /// A `float` field, omitted when its bit pattern is zero (+0.0); −0.0 and NaN are written.
    pub(crate) fn float(&mut self, field: u32, v: f32) {
        self.fixed32(field, v.to_bits());
    }
}

/// [`Reader::varint`] for two bytes or more (or none left) at `pos` of `buf`: the value and the
/// position after it. Takes and returns the position by value, so the caller's reader can stay in
/// registers.
#[inline(never)]
fn varint_long(buf: &[u8], pos: usize) -> Result<(u64, usize), DecodeError> {
    let mut at = pos;
    let mut value: u64 = 0;
    for i in 0..10u32 {
        let b = *buf.get(at).ok_or(DecodeError)?;
        // `at` < `buf.len()`, so one more is at most the length.
        at = at.wrapping_add(1);
        let bits = u64::from(b & 0x7F);
        // The tenth byte carries bit 63 only.
        if i == 9 && bits > 1 {
            return Err(DecodeError);
        }
        value |= bits.wrapping_shl(i.wrapping_mul(7));
        if b & 0x80 == 0 {
            return Ok((value, at));
        }
    }
    Err(DecodeError)
}

/// A field value as read from the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Value {
    /// Wire type 0.
    Varint(u64),
    /// Wire type 5.
    I32(u32),
    /// Wire type 1 (only skipped by this crate's messages).
    I64,
    /// Wire type 2 (only skipped by this crate's messages).
    Len,
}

/// Reads fields from a payload; every method returns an error rather than reading past the end.
///
/// A position into the payload rather than the rest of it as a slice: the same loads on the MCU,
/// and under Kani plain indexing instead of a pointer offset checked at every byte.
pub(crate) struct Reader<'a> {
    buf: &'a [u8],
    /// Bytes read: never more than `buf.len()`.
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader over the whole of `payload`.
    pub(crate) fn new(payload: &'a [u8]) -> Self {
        Self {
            buf: payload,
            pos: 0,
        }
    }

    /// Bytes not read yet.
    pub(crate) fn remaining(&self) -> usize {
        self.buf.len().saturating_sub(self.pos)
    }

    /// Skips `n` bytes.
    fn take(&mut self, n: usize) -> Result<(), DecodeError> {
        if n > self.remaining() {
            return Err(DecodeError);
        }
        // At most `buf.len()`: `n` is within what remains.
        self.pos = self.pos.wrapping_add(n);
        Ok(())
    }

    /// A varint of at most 10 bytes whose value fits 64 bits.
    ///
    /// Every key and every small value (mode, enable, version) of these messages is one byte:
    /// that case is inlined into the caller, longer varints take the out-of-line loop.
    #[inline(always)]
    fn varint(&mut self) -> Result<u64, DecodeError> {
        match self.buf.get(self.pos) {
            Some(&b) if b & 0x80 == 0 => {
                self.pos = self.pos.wrapping_add(1);
                Ok(u64::from(b))
            }
            _ => {
                let (value, pos) = varint_long(self.buf, self.pos)?;
                self.pos = pos;
                Ok(value)
            }
        }
    }

    /// Four bytes, little-endian.
    #[inline(always)]
    fn u32_le(&mut self) -> Result<u32, DecodeError> {
        let rest = self.buf.get(self.pos..).unwrap_or(&[]);
        let (&w, _) = rest.split_first_chunk::<4>().ok_or(DecodeError)?;
        // Four bytes were there, so `pos` stays within `buf.len()`.
        self.pos = self.pos.wrapping_add(4);
        Ok(u32::from_le_bytes(w))
    }

    /// The next field, or `None` at the end of the payload.
    ///
    /// Errors: truncated key or value, field number 0 or above 2²⁹ − 1, wire types 3, 4, 6, 7
    /// (groups are deprecated and unsupported, as in nanopb), a LEN field longer than the rest.
    pub(crate) fn next_field(&mut self) -> Result<Option<(u32, Value)>, DecodeError> {
        if self.remaining() == 0 {
            return Ok(None);
        }
        let key = self.varint()?;
        let field = u32::try_from(key >> 3).map_err(|_| DecodeError)?;
        if field == 0 || field > MAX_FIELD {
            return Err(DecodeError);
        }
        let value = match (key & 7) as u8 {
            WT_VARINT => Value::Varint(self.varint()?),
            WT_I64 => {
                self.take(8)?;
                Value::I64
            }
            WT_LEN => {
                let len = usize::try_from(self.varint()?).map_err(|_| DecodeError)?;
                self.take(len)?;
                Value::Len
            }
            WT_I32 => Value::I32(self.u32_le()?),
            _ => return Err(DecodeError),
        };
        Ok(Some((field, value)))
    }
}

impl Value {
    /// A `uint32` no larger than `max` (nanopb's `int_size` check); other wire types are errors.
    pub(crate) fn uint32_upto(self, max: u32) -> Result<u32, DecodeError> {
        match self {
            Value::Varint(v) if v <= u64::from(max) => u32::try_from(v).map_err(|_| DecodeError),
            _ => Err(DecodeError),
        }
    }

    /// A `uint32`.
    pub(crate) fn uint32(self) -> Result<u32, DecodeError> {
        self.uint32_upto(u32::MAX)
    }

    /// A `sint32` (the zigzag value must fit 32 bits).
    pub(crate) fn sint32(self) -> Result<i32, DecodeError> {
        self.uint32().map(unzigzag)
    }

    /// A `fixed32`.
    pub(crate) fn fixed32(self) -> Result<u32, DecodeError> {
        match self {
            Value::I32(v) => Ok(v),
            _ => Err(DecodeError),
        }
    }

    /// A `float`.
    pub(crate) fn float(self) -> Result<f32, DecodeError> {
        self.fixed32().map(f32::from_bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varint_lengths_match_the_protobuf_guide() {
        // 150 encodes as 96 01 (protobuf encoding guide).
        let mut buf = [0u8; 4];
        let mut w = Writer::new(&mut buf);
        w.varint(150);
        assert_eq!(w.len(), 2);
        assert_eq!(buf[..2], [0x96, 0x01]);
        assert_eq!(varint_len(0), 1);
        assert_eq!(varint_len(127), 1);
        assert_eq!(varint_len(128), 2);
        assert_eq!(varint_len(u64::from(u32::MAX)), 5);
        assert_eq!(varint_len(u64::MAX), 10);
    }

    #[test]
    fn zigzag_matches_the_guide_table() {
        for (v, z) in [
            (0, 0u32),
            (-1, 1),
            (1, 2),
            (-2, 3),
            (i32::MAX, 0xFFFF_FFFE),
            (i32::MIN, 0xFFFF_FFFF),
        ] {
            assert_eq!(zigzag(v), z);
            assert_eq!(unzigzag(z), v);
        }
    }

    #[test]
    fn reader_rejects_malformed_input() {
        for bad in [
            &[0x08][..],                  // key without value
            &[0x00, 0x00],                // field 0
            &[0x0B],                      // wire type 3 (group start)
            &[0x0C],                      // wire type 4 (group end)
            &[0x0E, 0x00],                // wire type 6
            &[0x12, 0x05, 0x01],          // LEN longer than the rest
            &[0x0D, 1, 2, 3],             // fixed32 truncated
            &[0x09, 1, 2, 3, 4, 5, 6, 7], // fixed64 truncated
            &[
                0x08, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01, 0x00,
            ], // 11-byte varint
            &[
                0x08, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x02,
            ], // bit 64 set
            &[0x80, 0x80, 0x80, 0x80, 0x10, 0x00], // field number 2^29 (one past the max)
        ] {
            let mut r = Reader::new(bad);
            let mut res = Ok(None);
            for _ in 0..4 {
                res = r.next_field();
                if !matches!(res, Ok(Some(_))) {
                    break;
                }
            }
            assert_eq!(res, Err(DecodeError), "{bad:02x?}");
        }
    }

    #[test]
    fn reader_takes_values_that_end_exactly_at_the_payload_end() {
        // fixed64 (field 1, wire type 1: key 0x09) and LEN (field 2, wire type 2: key 0x12, two
        // bytes) whose last byte is the payload's last: read whole, then the end.
        let mut r = Reader::new(&[0x09, 1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(r.next_field(), Ok(Some((1, Value::I64))));
        assert_eq!(r.next_field(), Ok(None));
        let mut r = Reader::new(&[0x12, 0x02, 0xAA, 0xBB]);
        assert_eq!(r.next_field(), Ok(Some((2, Value::Len))));
        assert_eq!(r.next_field(), Ok(None));
    }

    #[test]
    fn a_ten_byte_varint_may_carry_bit_63() {
        // 7 bits per byte: nine bytes carry bits 0 to 62, the tenth byte's lowest bit is bit 63.
        let mut top = [
            0x08, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x01,
        ];
        let mut r = Reader::new(&top);
        assert_eq!(r.next_field(), Ok(Some((1, Value::Varint(1 << 63)))));
        top[1..10].fill(0xFF);
        let mut r = Reader::new(&top);
        assert_eq!(r.next_field(), Ok(Some((1, Value::Varint(u64::MAX)))));
    }

    #[test]
    fn reader_accepts_max_field_and_overlong_zero_padding() {
        // Field 2^29 - 1, varint 0 written in two bytes (80 00): legal protobuf.
        let mut r = Reader::new(&[0xF8, 0xFF, 0xFF, 0xFF, 0x0F, 0x80, 0x00]);
        assert_eq!(r.next_field(), Ok(Some((MAX_FIELD, Value::Varint(0)))));
        assert_eq!(r.next_field(), Ok(None));
    }
}
