//! Bit-level writer and reader in DCCL's bit order.
//!
//! DCCL packs fields one after the other starting at the least significant bit
//! of the first byte; a value of `n` bits is written least significant bit
//! first. Reading past the end is an error, never a panic.

use crate::error::CodecError;

/// Appends bit fields to a byte buffer, least significant bit first.
#[derive(Debug, Default, Clone)]
pub struct BitWriter {
    bytes: Vec<u8>,
    len: usize,
}

impl BitWriter {
    /// An empty writer.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty writer with room for `bytes` bytes.
    pub fn with_capacity(bytes: usize) -> Self {
        BitWriter {
            bytes: Vec::with_capacity(bytes),
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
        self.bytes.reserve(additional);
    }

    /// Number of bits written so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing has been written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Writes the `nbits` low bits of `value` (bits above bit 63 are zero).
    #[inline]
    pub fn write(&mut self, value: u64, nbits: u32) {
        if nbits == 0 {
            return;
        }
        if nbits > 64 {
            self.write(value, 64);
            self.write_zeros(nbits as usize - 64);
            return;
        }
        let value = if nbits == 64 {
            value
        } else {
            value & ((1u64 << nbits) - 1)
        };
        // The bytes hold exactly `len.div_ceil(8)` bytes and the bits of the
        // last one beyond `len` are zero: the value, shifted to the first
        // free bit, is OR-ed into that byte and the rest appended.
        let bit = (self.len % 8) as u32;
        let mut shifted = (value as u128) << bit;
        let end = self.len + nbits as usize;
        if bit != 0 {
            if let Some(last) = self.bytes.last_mut() {
                *last |= shifted as u8;
            }
            shifted >>= 8;
        }
        // All 16 bytes are appended (a fixed-size copy), then the length
        // cut back to the bytes the value reaches.
        let keep = end.div_ceil(8);
        self.bytes.extend_from_slice(&shifted.to_le_bytes());
        self.bytes.truncate(keep);
        self.len = end;
    }

    /// Writes one bit.
    pub fn write_bool(&mut self, bit: bool) {
        self.write(bit as u64, 1);
    }

    /// Writes whole bytes, each least significant bit first.
    pub fn write_bytes(&mut self, bytes: &[u8]) {
        if self.len.is_multiple_of(8) {
            self.bytes.extend_from_slice(bytes);
            self.len += bytes.len() * 8;
        } else {
            let mut chunks = bytes.chunks_exact(8);
            for chunk in &mut chunks {
                let mut word = [0u8; 8];
                word.copy_from_slice(chunk);
                self.write(u64::from_le_bytes(word), 64);
            }
            for b in chunks.remainder() {
                self.write(*b as u64, 8);
            }
        }
    }

    /// Writes `nbits` zero bits.
    pub fn write_zeros(&mut self, nbits: usize) {
        // Bits beyond `len` are already zero: only whole bytes are added.
        self.len += nbits;
        self.bytes.resize(self.len.div_ceil(8), 0);
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
    pub fn pad_to_byte(&mut self) {
        self.len = self.bytes.len() * 8;
    }

    /// The bytes written (the last one zero-padded).
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Consumes the writer, returning the bytes (the last one zero-padded).
    pub fn into_bytes(self) -> Vec<u8> {
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

    /// Reads `nbits` bits as an unsigned integer. Bits beyond the 64th are
    /// consumed and must be zero-valued only in the sense that they are dropped.
    #[inline]
    pub fn read(&mut self, nbits: u32) -> Result<u64, CodecError> {
        self.need(nbits as usize)?;
        let byte = self.pos / 8;
        let bit = (self.pos % 8) as u32;
        if nbits + bit <= 64 {
            if let Some(word) = self.bytes.get(byte..byte + 8) {
                let mut w = [0u8; 8];
                w.copy_from_slice(word);
                self.pos += nbits as usize;
                return Ok(low_bits(u64::from_le_bytes(w) >> bit, nbits));
            }
        }
        Ok(self.read_slow(nbits))
    }

    /// [`BitReader::read`] near the end of the bytes or over 56 bits (the
    /// length already checked).
    fn read_slow(&mut self, nbits: u32) -> u64 {
        let mut out = 0u64;
        let mut got = 0u32;
        while got < nbits {
            let byte = self.bytes[self.pos / 8];
            let bit_in_byte = (self.pos % 8) as u32;
            let take = (8 - bit_in_byte).min(nbits - got);
            let chunk = ((byte >> bit_in_byte) as u64) & ((1u64 << take) - 1);
            if got < 64 {
                out |= chunk << got;
            }
            got += take;
            self.pos += take as usize;
        }
        out
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
        let mut out = Vec::with_capacity(n);
        let mut left = n;
        while left >= 7 {
            out.extend_from_slice(&self.read(56)?.to_le_bytes()[..7]);
            left -= 7;
        }
        for _ in 0..left {
            out.push(self.read(8)? as u8);
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
