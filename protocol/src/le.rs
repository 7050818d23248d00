//! Little-endian field cursors over byte slices for the packed C layouts of seeds 001, 003 and 004; no panics.
//!
//! Fixed-size fields are copied byte by byte with `for i in 0..N` over `[u8; N]`, not with
//! `copy_from_slice` or slice iterators: the same code on the MCU, and under Kani no pointer
//! arithmetic to execute per byte (the seed 004 round-trip harnesses took half the time;
//! `proofs/REPORT.md`, "Kani suite time").

/// The slice ended before the field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Short;

/// Reads little-endian fields in order.
pub(crate) struct Reader<'a> {
    rest: &'a [u8],
}

impl<'a> Reader<'a> {
    /// A reader at the start of `buf`.
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Self { rest: buf }
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], Short> {
        if self.rest.len() < N {
            return Err(Short);
        }
        let (head, tail) = self.rest.split_at(N);
        self.rest = tail;
        let mut out = [0u8; N];
        #[allow(clippy::indexing_slicing, clippy::manual_memcpy)]
        for i in 0..N {
            out[i] = head[i];
        }
        Ok(out)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, Short> {
        self.array::<1>().map(|[b]| b)
    }
    pub(crate) fn i8(&mut self) -> Result<i8, Short> {
        self.array::<1>().map(i8::from_le_bytes)
    }
    pub(crate) fn u16(&mut self) -> Result<u16, Short> {
        self.array().map(u16::from_le_bytes)
    }
    pub(crate) fn i16(&mut self) -> Result<i16, Short> {
        self.array().map(i16::from_le_bytes)
    }
    pub(crate) fn u32(&mut self) -> Result<u32, Short> {
        self.array().map(u32::from_le_bytes)
    }
    pub(crate) fn i32(&mut self) -> Result<i32, Short> {
        self.array().map(i32::from_le_bytes)
    }
    pub(crate) fn f32(&mut self) -> Result<f32, Short> {
        self.array().map(f32::from_le_bytes)
    }
}

/// Writes little-endian fields in order; bytes past the end are dropped and counted as a shortfall.
pub(crate) struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
    short: bool,
}

impl<'a> Writer<'a> {
    /// A writer at the start of `buf`.
    pub(crate) fn new(buf: &'a mut [u8]) -> Self {
        Self {
            buf,
            pos: 0,
            short: false,
        }
    }

    /// Bytes written.
    pub(crate) fn len(&self) -> usize {
        self.pos
    }

    /// `Ok(len)` if everything fitted.
    pub(crate) fn finish(&self) -> Result<usize, Short> {
        if self.short {
            Err(Short)
        } else {
            Ok(self.pos)
        }
    }

    /// Writes one byte at the cursor, or marks the writer short where the buffer has ended.
    fn byte(&mut self, b: u8) {
        match self.buf.get_mut(self.pos) {
            Some(slot) => {
                *slot = b;
                self.pos = self.pos.saturating_add(1);
            }
            None => self.short = true,
        }
    }
    pub(crate) fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.byte(b);
        }
    }
    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
        for i in 0..N {
            self.byte(bytes[i]);
        }
    }
    pub(crate) fn u8(&mut self, v: u8) {
        self.put([v]);
    }
    pub(crate) fn i8(&mut self, v: i8) {
        self.put(v.to_le_bytes());
    }
    pub(crate) fn u16(&mut self, v: u16) {
        self.put(v.to_le_bytes());
    }
    pub(crate) fn i16(&mut self, v: i16) {
        self.put(v.to_le_bytes());
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }
    pub(crate) fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes());
    }
    pub(crate) fn f32(&mut self, v: f32) {
        self.put(v.to_le_bytes());
    }

    /// Writes every element of `vs` with `put` (e.g. `w.each(&speeds, Writer::f32)`): one plain loop
    /// per array, which a model checker unrolls to its exact length (an iterator `chain` leaves it a
    /// merged state whose end it cannot see, so it unrolls to the harness bound).
    pub(crate) fn each<T: Copy, const N: usize>(
        &mut self,
        vs: &[T; N],
        put: impl Fn(&mut Self, T),
    ) {
        #[allow(clippy::indexing_slicing, clippy::needless_range_loop)]
        for i in 0..N {
            put(self, vs[i]);
        }
    }
}
