//! Bit-level writer and reader in DCCL's bit order.
//!
//! DCCL packs fields one after the other starting at the least significant bit
//! of the first byte; a value of `n` bits is written least significant bit
//! first. Reading past the end is an error, never a panic.

use crate::error::CodecError;

/// Appends bit fields to a byte buffer, least significant bit first.
///
/// Values are OR-ed into the buffer one 64-bit word at a time: the buffer
/// is kept at least 8 bytes longer than what is written, those bytes zero,
/// so that a value of up to 57 bits lands with one load and one store
/// whatever its bit offset. The bytes handed out are those written.
#[derive(Debug, Default, Clone)]
pub struct BitWriter {
    /// The bytes written, then zero bytes (at least [`SLACK`] once anything
    /// is written).
    bytes: Vec<u8>,
    /// Bits written.
    len: usize,
}

/// Zero bytes kept after the last byte written: one word's load and store.
const SLACK: usize = 8;

/// The widest value written or read with one word (a value of 56 bits at
/// bit offset 7 of its first byte ends in the word's last byte).
const WORD_BITS: u32 = 57;

impl BitWriter {
    /// An empty writer.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty writer with room for `bytes` bytes.
    pub fn with_capacity(bytes: usize) -> Self {
        BitWriter {
            bytes: Vec::with_capacity(bytes + SLACK),
            len: 0,
        }
    }

    /// A writer appending to `bytes` (from its end, a byte boundary):
    /// [`BitWriter::into_bytes`] gives them back followed by what was written.
    pub fn from_bytes(bytes: Vec<u8>) -> Self {
        BitWriter {
            len: bytes.len() * 8,
            bytes,
        }
    }

    /// Makes room for at least `additional` more bytes.
    pub fn reserve(&mut self, additional: usize) {
        // The room is zero bytes already there: writing needs no growing.
        let end = self.used() + additional + SLACK;
        if self.bytes.len() < end {
            self.bytes.resize(end, 0);
        }
    }

    /// Number of bits written so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing has been written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes the bits written take (the last one maybe partly).
    #[inline]
    fn used(&self) -> usize {
        self.len.div_ceil(8)
    }

    /// Makes the buffer hold at least `end` bytes (zeros past those written).
    #[inline]
    fn ensure(&mut self, end: usize) {
        if self.bytes.len() < end {
            self.grow(end);
        }
    }

    #[cold]
    #[inline(never)]
    fn grow(&mut self, end: usize) {
        let target = end.max(2 * self.bytes.len()).max(64);
        self.bytes.resize(target, 0);
    }

    /// ORs `value` (at most [`WORD_BITS`] bits, nothing above them) in at
    /// the bit `self.len`.
    #[inline]
    fn put_word(&mut self, value: u64, nbits: u32) {
        let byte = self.len / 8;
        self.ensure(byte + SLACK);
        let slot: &mut [u8; 8] = (&mut self.bytes[byte..byte + 8])
            .try_into()
            .expect("an 8-byte slice");
        let word = u64::from_le_bytes(*slot) | (value << (self.len % 8));
        *slot = word.to_le_bytes();
        self.len += nbits as usize;
    }

    /// Writes the `nbits` low bits of `value` (bits above bit 63 are zero).
    #[inline]
    pub fn write(&mut self, value: u64, nbits: u32) {
        if nbits <= WORD_BITS {
            self.put_word(low_bits(value, nbits), nbits);
        } else {
            self.write_wide(value, nbits);
        }
    }

    /// [`BitWriter::write`] of more than [`WORD_BITS`] bits.
    fn write_wide(&mut self, value: u64, nbits: u32) {
        self.put_word(value & 0xffff_ffff, 32);
        let high = nbits.min(64) - 32;
        self.put_word(low_bits(value >> 32, high), high);
        if nbits > 64 {
            self.write_zeros(nbits as usize - 64);
        }
    }

    /// Writes one bit.
    #[inline]
    pub fn write_bool(&mut self, bit: bool) {
        self.put_word(bit as u64, 1);
    }

    /// Writes whole bytes, each least significant bit first.
    pub fn write_bytes(&mut self, bytes: &[u8]) {
        if self.len.is_multiple_of(8) {
            let start = self.len / 8;
            self.ensure(start + bytes.len() + SLACK);
            self.bytes[start..start + bytes.len()].copy_from_slice(bytes);
            self.len += bytes.len() * 8;
        } else {
            // Seven bytes at a time: one word each.
            let mut chunks = bytes.chunks_exact(7);
            for chunk in &mut chunks {
                let mut word = [0u8; 8];
                word[..7].copy_from_slice(chunk);
                self.put_word(u64::from_le_bytes(word), 56);
            }
            let rest = chunks.remainder();
            if !rest.is_empty() {
                let mut word = [0u8; 8];
                word[..rest.len()].copy_from_slice(rest);
                self.put_word(u64::from_le_bytes(word), 8 * rest.len() as u32);
            }
        }
    }

    /// Writes `nbits` zero bits.
    #[inline]
    pub fn write_zeros(&mut self, nbits: usize) {
        // Bits beyond `len` are already zero.
        self.len += nbits;
        self.ensure(self.used());
    }

    /// Appends every bit of another writer.
    pub fn append(&mut self, other: &BitWriter) {
        let full = other.len / 8;
        self.write_bytes(&other.bytes[..full]);
        let rest = other.len % 8;
        if rest > 0 {
            self.write(other.bytes[full] as u64, rest as u32);
        }
    }

    /// Pads with zero bits up to a whole byte.
    #[inline]
    pub fn pad_to_byte(&mut self) {
        self.len = self.used() * 8;
    }

    /// The bytes written (the last one zero-padded).
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.used()]
    }

    /// Consumes the writer, returning the bytes (the last one zero-padded).
    pub fn into_bytes(mut self) -> Vec<u8> {
        self.bytes.truncate(self.used());
        self.bytes
    }

    /// Empties the writer, keeping its allocation.
    pub fn clear(&mut self) {
        self.bytes.clear();
        self.len = 0;
    }
}

/// The `nbits` low bits of `value` (all of them for 64 or more).
#[inline]
fn low_bits(value: u64, nbits: u32) -> u64 {
    if nbits >= 64 {
        value
    } else {
        value & ((1u64 << nbits) - 1)
    }
}

/// Reads bit fields from a byte slice, least significant bit first.
#[derive(Debug, Clone)]
pub struct BitReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> BitReader<'a> {
    /// A reader at the first bit of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        BitReader { bytes, pos: 0 }
    }

    /// Bits consumed so far.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Bits left to read.
    pub fn remaining(&self) -> usize {
        self.bytes.len() * 8 - self.pos
    }

    /// Whole bytes touched so far (a partly read byte counts).
    pub fn bytes_consumed(&self) -> usize {
        self.pos.div_ceil(8)
    }

    #[inline]
    fn need(&self, nbits: usize) -> Result<(), CodecError> {
        if nbits > self.remaining() {
            Err(self.truncated(nbits))
        } else {
            Ok(())
        }
    }

    #[cold]
    #[inline(never)]
    fn truncated(&self, nbits: usize) -> CodecError {
        CodecError::new(format!(
            "message is truncated: needed {nbits} more bits at bit {}, only {} left",
            self.pos,
            self.remaining()
        ))
    }

    /// The 64 bits from bit `pos` on (zeros past the end), of which the
    /// first [`WORD_BITS`] at least are those of the bytes.
    #[inline]
    fn word_at(&self, pos: usize) -> u64 {
        let byte = pos / 8;
        let word = match self.bytes.get(byte..byte + 8) {
            Some(w) => u64::from_le_bytes(w.try_into().expect("an 8-byte slice")),
            None => self.tail_word(byte),
        };
        word >> (pos % 8)
    }

    /// The bytes from `byte` on, fewer than 8, as a word (zeros after them).
    #[inline]
    fn tail_word(&self, byte: usize) -> u64 {
        let len = self.bytes.len();
        if byte >= len {
            return 0;
        }
        match self.bytes.get(len.wrapping_sub(8)..) {
            // The last 8 bytes, shifted down to start at `byte`.
            Some(last) => {
                u64::from_le_bytes(last.try_into().expect("an 8-byte slice"))
                    >> (8 * (byte + 8 - len))
            }
            None => self.bytes[byte..]
                .iter()
                .rev()
                .fold(0, |w, b| w << 8 | u64::from(*b)),
        }
    }

    /// Reads `nbits` bits as an unsigned integer. Bits beyond the 64th are
    /// consumed and must be zero-valued only in the sense that they are dropped.
    #[inline]
    pub fn read(&mut self, nbits: u32) -> Result<u64, CodecError> {
        self.need(nbits as usize)?;
        if nbits > WORD_BITS {
            return Ok(self.read_wide(nbits));
        }
        let value = low_bits(self.word_at(self.pos), nbits);
        self.pos += nbits as usize;
        Ok(value)
    }

    /// [`BitReader::read`] of more than [`WORD_BITS`] bits (the length
    /// already checked).
    fn read_wide(&mut self, nbits: u32) -> u64 {
        let low = low_bits(self.word_at(self.pos), 32);
        let high_bits = nbits.min(64) - 32;
        let high = low_bits(self.word_at(self.pos + 32), high_bits);
        self.pos += nbits as usize;
        low | high << 32
    }

    /// Reads one bit.
    pub fn read_bool(&mut self) -> Result<bool, CodecError> {
        Ok(self.read(1)? != 0)
    }

    /// Looks at the next bit without consuming it.
    pub fn peek_bool(&self) -> Result<bool, CodecError> {
        self.need(1)?;
        Ok((self.bytes[self.pos / 8] >> (self.pos % 8)) & 1 != 0)
    }

    /// Reads `n` whole bytes.
    pub fn read_bytes(&mut self, n: usize) -> Result<Vec<u8>, CodecError> {
        self.need(n * 8)?;
        if self.pos.is_multiple_of(8) {
            let start = self.pos / 8;
            self.pos += n * 8;
            return Ok(self.bytes[start..start + n].to_vec());
        }
        // Seven bytes at a time: one word each.
        let mut out = Vec::with_capacity(n);
        let mut left = n;
        while left > 0 {
            let take = left.min(7);
            out.extend_from_slice(&self.word_at(self.pos).to_le_bytes()[..take]);
            self.pos += take * 8;
            left -= take;
        }
        Ok(out)
    }

    /// Skips `nbits` bits.
    pub fn skip(&mut self, nbits: usize) -> Result<(), CodecError> {
        self.need(nbits)?;
        self.pos += nbits;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_least_significant_bit_first() {
        let mut w = BitWriter::new();
        w.write(10 << 1, 8);
        w.write(0b101, 3);
        w.write(0x3ff, 10);
        assert_eq!(w.len(), 21);
        assert_eq!(w.as_bytes(), &[0x14, 0xfd, 0x1f]);
        let mut r = BitReader::new(w.as_bytes());
        assert_eq!(r.read(8).unwrap(), 20);
        assert_eq!(r.read(3).unwrap(), 5);
        assert_eq!(r.read(10).unwrap(), 0x3ff);
        assert_eq!(r.bytes_consumed(), 3);
        assert!(r.read(4).is_err());
    }

    #[test]
    fn wide_values_and_unaligned_bytes() {
        let mut w = BitWriter::new();
        w.write_bool(true);
        w.write(u64::MAX, 64);
        w.write_bytes(b"ab");
        w.write_zeros(70);
        let mut r = BitReader::new(w.as_bytes());
        assert!(r.read_bool().unwrap());
        assert_eq!(r.read(64).unwrap(), u64::MAX);
        assert_eq!(r.read_bytes(2).unwrap(), b"ab");
        assert_eq!(r.read(64).unwrap(), 0);
        let mut other = BitWriter::new();
        other.write(0b11, 2);
        w.append(&other);
        assert_eq!(w.len(), 1 + 64 + 16 + 70 + 2);
    }

    /// The writer and the reader agree, bit for bit, with a plain
    /// one-bit-at-a-time model on random field widths (0 to 70 bits) at
    /// every alignment, whole bytes and zero runs included.
    #[test]
    fn agree_with_a_bit_at_a_time_model() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200 {
            let mut w = BitWriter::new();
            let mut model: Vec<bool> = Vec::new();
            let mut fields = Vec::new();
            for _ in 0..(next() % 40) {
                match next() % 4 {
                    0 => {
                        let n = (next() % 12) as usize;
                        let bytes: Vec<u8> = (0..n).map(|_| next() as u8).collect();
                        w.write_bytes(&bytes);
                        for b in &bytes {
                            model.extend((0..8).map(|i| b >> i & 1 != 0));
                        }
                        fields.push((2, n as u32, 0, bytes));
                    }
                    1 => {
                        let n = (next() % 80) as usize;
                        w.write_zeros(n);
                        model.extend(std::iter::repeat_n(false, n));
                        fields.push((1, n as u32, 0, Vec::new()));
                    }
                    _ => {
                        let nbits = (next() % 71) as u32;
                        let value = next();
                        w.write(value, nbits);
                        model.extend((0..nbits).map(|i| i < 64 && value >> i & 1 != 0));
                        let kept = if nbits >= 64 {
                            value
                        } else {
                            value & ((1u64 << nbits) - 1)
                        };
                        fields.push((0, nbits, kept, Vec::new()));
                    }
                }
                assert_eq!(w.len(), model.len());
            }
            let mut expected = vec![0u8; model.len().div_ceil(8)];
            for (i, bit) in model.iter().enumerate() {
                expected[i / 8] |= u8::from(*bit) << (i % 8);
            }
            assert_eq!(w.as_bytes(), &expected[..]);
            let mut r = BitReader::new(w.as_bytes());
            for (kind, n, value, bytes) in fields {
                match kind {
                    0 => assert_eq!(r.read(n).unwrap(), value),
                    1 => r.skip(n as usize).unwrap(),
                    _ => assert_eq!(r.read_bytes(n as usize).unwrap(), bytes),
                }
            }
            assert_eq!(r.position(), model.len());
            assert!(r.remaining() < 8);
        }
    }
}
