//! Splitting the byte stream of an AT serial line into lines and the binary
//! blocks between them (sans-IO: bytes are pushed in, units taken out).
//!
//! Lines end with CR or LF (a transceiver ends its lines with CR LF, a
//! host its commands with CR); empty lines are skipped. The party that
//! asked for a binary block says so before its bytes come:
//! [`Reader::expect_mt_message`] for the answer to `AT+SBDRB` (2-byte
//! length, message, 2-byte checksum), [`Reader::expect_bytes`] for a block
//! of known length (the message and checksum after `AT+SBDWB`'s `READY`).

/// Longest line kept; a longer run of bytes without line end is handed
/// up as one line (the parser then rejects it), so that memory stays
/// bounded.
pub const MAX_LINE: usize = 4096;

/// Largest SBD message a transceiver holds in its MT buffer (bytes); an
/// `AT+SBDRB` length above it is not a length.
pub const MAX_MT_LENGTH: usize = 1960;

/// What the stream held.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Unit {
    /// A line, its end removed.
    Line(Vec<u8>),
    /// The answer to `AT+SBDRB`: the message and the checksum that
    /// followed it (not checked here).
    MtMessage {
        /// The message.
        message: Vec<u8>,
        /// The checksum the transceiver gave.
        checksum: u16,
    },
    /// A block of the length asked for by [`Reader::expect_bytes`].
    Bytes(Vec<u8>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Lines,
    MtMessage,
    Bytes(usize),
}

/// The stream's bytes not yet taken, and what comes next.
#[derive(Debug)]
pub struct Reader {
    buffer: Vec<u8>,
    mode: Mode,
}

impl Default for Reader {
    fn default() -> Self {
        Reader::new()
    }
}

impl Reader {
    /// A reader expecting lines.
    pub fn new() -> Reader {
        Reader {
            buffer: Vec::new(),
            mode: Mode::Lines,
        }
    }

    /// Bytes read from the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buffer.extend_from_slice(bytes);
    }

    /// The answer to `AT+SBDRB` comes next (lines that come first are still
    /// taken as lines: their first byte would make a length above
    /// [`MAX_MT_LENGTH`]).
    pub fn expect_mt_message(&mut self) {
        self.mode = Mode::MtMessage;
    }

    /// A block of `n` bytes comes next.
    pub fn expect_bytes(&mut self, n: usize) {
        self.mode = Mode::Bytes(n);
    }

    /// Back to lines: a binary block expected is given up (what was read of
    /// it is dropped).
    pub fn expect_lines(&mut self) -> Vec<u8> {
        let dropped = match self.mode {
            Mode::Lines => Vec::new(),
            _ => std::mem::take(&mut self.buffer),
        };
        self.mode = Mode::Lines;
        dropped
    }

    /// Whether a binary block is expected.
    pub fn in_binary(&self) -> bool {
        self.mode != Mode::Lines
    }

    /// Bytes held, not yet a unit.
    pub fn pending(&self) -> usize {
        self.buffer.len()
    }

    /// The next unit, when the bytes pushed hold one.
    pub fn next_unit(&mut self) -> Option<Unit> {
        loop {
            match self.mode {
                Mode::Lines => return self.line(),
                Mode::Bytes(n) => {
                    if self.buffer.len() < n {
                        return None;
                    }
                    let block: Vec<u8> = self.buffer.drain(..n).collect();
                    self.mode = Mode::Lines;
                    return Some(Unit::Bytes(block));
                }
                Mode::MtMessage => {
                    // Line ends left from the line before.
                    let ends = self
                        .buffer
                        .iter()
                        .take_while(|&&b| b == b'\r' || b == b'\n')
                        .count();
                    self.buffer.drain(..ends);
                    let first = *self.buffer.first()?;
                    if usize::from(first) << 8 > MAX_MT_LENGTH {
                        // Text: a line before the answer.
                        match self.line() {
                            Some(line) => return Some(line),
                            None => return None,
                        }
                    }
                    if self.buffer.len() < 2 {
                        return None;
                    }
                    let length = usize::from(u16::from_be_bytes([self.buffer[0], self.buffer[1]]));
                    if length > MAX_MT_LENGTH {
                        // Not a length: read on as lines.
                        self.mode = Mode::Lines;
                        continue;
                    }
                    if self.buffer.len() < 2 + length + 2 {
                        return None;
                    }
                    let block: Vec<u8> = self.buffer.drain(..2 + length + 2).collect();
                    self.mode = Mode::Lines;
                    let checksum = u16::from_be_bytes([block[2 + length], block[3 + length]]);
                    return Some(Unit::MtMessage {
                        message: block[2..2 + length].to_vec(),
                        checksum,
                    });
                }
            }
        }
    }

    fn line(&mut self) -> Option<Unit> {
        loop {
            match self.buffer.iter().position(|&b| b == b'\r' || b == b'\n') {
                Some(0) => {
                    self.buffer.remove(0);
                }
                Some(end) => {
                    let line: Vec<u8> = self.buffer.drain(..end).collect();
                    self.buffer.remove(0);
                    return Some(Unit::Line(line));
                }
                None if self.buffer.len() >= MAX_LINE => {
                    return Some(Unit::Line(std::mem::take(&mut self.buffer)));
                }
                None => return None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn all(reader: &mut Reader) -> Vec<Unit> {
        std::iter::from_fn(|| reader.next_unit()).collect()
    }

    #[test]
    fn lines_end_with_cr_or_lf_and_empty_ones_vanish() {
        let mut r = Reader::new();
        r.push(b"\r\nOK\r\n\r\n+CIEV:0,3\r\nREA");
        assert_eq!(
            all(&mut r),
            vec![
                Unit::Line(b"OK".to_vec()),
                Unit::Line(b"+CIEV:0,3".to_vec())
            ]
        );
        r.push(b"DY\r");
        assert_eq!(all(&mut r), vec![Unit::Line(b"READY".to_vec())]);
    }

    #[test]
    fn the_answer_to_sbdrb_is_read_whole_even_with_line_ends_inside() {
        let mut r = Reader::new();
        r.expect_mt_message();
        // A ring alert first, then the answer: length 3, "a\r\n", checksum.
        r.push(b"SBDRING\r\n\x00\x03a\r");
        assert_eq!(all(&mut r), vec![Unit::Line(b"SBDRING".to_vec())]);
        assert!(r.in_binary());
        r.push(b"\n\x00\x78\r\nOK\r\n");
        assert_eq!(
            all(&mut r),
            vec![
                Unit::MtMessage {
                    message: b"a\r\n".to_vec(),
                    checksum: 0x78
                },
                Unit::Line(b"OK".to_vec())
            ]
        );
        assert!(!r.in_binary());
    }

    #[test]
    fn blocks_of_known_length() {
        let mut r = Reader::new();
        r.push(b"AT+SBDWB=2\r");
        assert_eq!(all(&mut r), vec![Unit::Line(b"AT+SBDWB=2".to_vec())]);
        r.expect_bytes(4);
        r.push(b"\r\n\x00");
        assert_eq!(all(&mut r), vec![]);
        r.push(b"\x17AT\r");
        assert_eq!(
            all(&mut r),
            vec![
                Unit::Bytes(b"\r\n\x00\x17".to_vec()),
                Unit::Line(b"AT".to_vec())
            ]
        );
        r.expect_bytes(10);
        r.push(b"abc");
        assert_eq!(r.expect_lines(), b"abc");
    }

    #[test]
    fn long_runs_without_line_end_are_bounded() {
        let mut r = Reader::new();
        r.push(&vec![b'x'; MAX_LINE + 5]);
        let Some(Unit::Line(line)) = r.next_unit() else {
            panic!()
        };
        assert_eq!(line.len(), MAX_LINE + 5);
    }

    proptest! {
        #[test]
        fn any_bytes_in_any_mode_never_panic(
            chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 0..8),
            mode in 0..3u8,
        ) {
            let mut r = Reader::new();
            match mode {
                0 => {}
                1 => r.expect_mt_message(),
                _ => r.expect_bytes(7),
            }
            for c in chunks {
                r.push(&c);
                while r.next_unit().is_some() {}
            }
        }
    }
}
