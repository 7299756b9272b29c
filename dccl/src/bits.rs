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

    /// Number of bits written so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing has been written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Writes the `nbits` low bits of `value` (bits above bit 63 are zero).
    pub fn write(&mut self, value: u64, nbits: u32) {
        let mut remaining = nbits as usize;
        let mut value = if nbits >= 64 {
            value
        } else {
            value & ((1u64 << nbits) - 1)
        };
        let mut written_value_bits = 0usize;
        while remaining > 0 {
            let bit_in_byte = self.len % 8;
            if bit_in_byte == 0 {
                self.bytes.push(0);
            }
            let room = 8 - bit_in_byte;
            let take = room.min(remaining);
            let chunk = if written_value_bits >= 64 {
                0
            } else {
                (value & ((1u64 << take) - 1)) as u8
            };
            let last = self.bytes.len() - 1;
            self.bytes[last] |= chunk << bit_in_byte;
            value = if take >= 64 { 0 } else { value >> take };
            written_value_bits += take;
            remaining -= take;
            self.len += take;
        }
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
            for b in bytes {
                self.write(*b as u64, 8);
            }
        }
    }

    /// Writes `nbits` zero bits.
    pub fn write_zeros(&mut self, nbits: usize) {
        let mut left = nbits;
        while left > 0 {
            let n = left.min(64);
            self.write(0, n as u32);
            left -= n;
        }
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

    fn need(&self, nbits: usize) -> Result<(), CodecError> {
        if nbits > self.remaining() {
            Err(CodecError::new(format!(
                "message is truncated: needed {nbits} more bits at bit {}, only {} left",
                self.pos,
                self.remaining()
            )))
        } else {
            Ok(())
        }
    }

    /// Reads `nbits` bits as an unsigned integer. Bits beyond the 64th are
    /// consumed and must be zero-valued only in the sense that they are dropped.
    pub fn read(&mut self, nbits: u32) -> Result<u64, CodecError> {
        self.need(nbits as usize)?;
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
        Ok(out)
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
        for _ in 0..n {
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
}
