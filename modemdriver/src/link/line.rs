//! Lines over a byte stream (serial port, TCP, pseudo-terminal): read from
//! the stream ([`LineLink`]), or split out of the bytes a driver reads
//! itself ([`LineSplitter`]).

use std::io;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::Link;

/// Longest line kept; a longer run of bytes without a delimiter is handed up
/// as one unit (the parser above rejects it) so that memory stays bounded.
pub const MAX_LINE: usize = 4096;

/// Splits a byte stream into lines ending with a delimiter, and writes lines
/// followed by it.
///
/// Reading splits on the delimiter's last byte and removes the rest of the
/// delimiter when present, so "\r\n" lines also accept a bare "\n".
#[derive(Debug)]
pub struct LineLink<S> {
    stream: S,
    delimiter: Vec<u8>,
    buffer: Vec<u8>,
}

impl<S> LineLink<S> {
    /// Wraps `stream`; an empty delimiter means "\r\n".
    pub fn new(stream: S, delimiter: &[u8]) -> Self {
        let delimiter = if delimiter.is_empty() {
            b"\r\n".to_vec()
        } else {
            delimiter.to_vec()
        };
        LineLink {
            stream,
            delimiter,
            buffer: Vec::new(),
        }
    }

    /// The stream underneath.
    pub fn get_ref(&self) -> &S {
        &self.stream
    }

    fn take_line(&mut self) -> Option<Vec<u8>> {
        let last = *self.delimiter.last()?;
        if let Some(pos) = self.buffer.iter().position(|&b| b == last) {
            let mut line: Vec<u8> = self.buffer.drain(..=pos).collect();
            line.pop();
            let rest = &self.delimiter[..self.delimiter.len() - 1];
            if line.ends_with(rest) {
                line.truncate(line.len() - rest.len());
            }
            return Some(line);
        }
        if self.buffer.len() >= MAX_LINE {
            return Some(std::mem::take(&mut self.buffer));
        }
        None
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin + Send> Link for LineLink<S> {
    type Peer = ();

    async fn recv(&mut self) -> io::Result<(Vec<u8>, ())> {
        loop {
            if let Some(line) = self.take_line() {
                return Ok((line, ()));
            }
            let mut chunk = [0u8; 512];
            // `read` is cancel-safe: bytes are only kept once it completes.
            let n = self.stream.read(&mut chunk).await?;
            if n == 0 {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the device closed",
                ));
            }
            self.buffer.extend_from_slice(&chunk[..n]);
        }
    }

    async fn send(&mut self, unit: &[u8], _peer: &()) -> io::Result<()> {
        let mut out = Vec::with_capacity(unit.len() + self.delimiter.len());
        out.extend_from_slice(unit);
        out.extend_from_slice(&self.delimiter);
        self.stream.write_all(&out).await?;
        self.stream.flush().await
    }
}

/// Splits bytes into lines ended by CR or LF, for a driver that reads its
/// modem's stream as bytes (its writes are not all lines); empty lines are
/// skipped, and a run of `max` bytes without an end is given as a line.
#[derive(Debug)]
pub struct LineSplitter {
    buf: Vec<u8>,
    max: usize,
}

impl LineSplitter {
    /// A splitter with nothing buffered, giving lines of at most `max`
    /// bytes.
    pub fn new(max: usize) -> Self {
        LineSplitter {
            buf: Vec::new(),
            max: max.max(1),
        }
    }

    /// Forgets what is buffered (the link was lost).
    pub fn clear(&mut self) {
        self.buf.clear();
    }

    /// The lines `bytes` complete, in order.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                if !self.buf.is_empty() {
                    out.push(std::mem::take(&mut self.buf));
                }
            } else {
                self.buf.push(b);
                if self.buf.len() >= self.max {
                    out.push(std::mem::take(&mut self.buf));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn splits_lines_and_accepts_bare_newlines() {
        let (a, mut b) = tokio::io::duplex(1024);
        let mut link = LineLink::new(a, b"\r\n");
        b.write_all(b"$ONE*00\r\n$TWO\n$THR").await.unwrap();
        assert_eq!(link.recv().await.unwrap().0, b"$ONE*00");
        assert_eq!(link.recv().await.unwrap().0, b"$TWO");
        b.write_all(b"EE\r\n").await.unwrap();
        assert_eq!(link.recv().await.unwrap().0, b"$THREE");
        link.send(b"$OUT", &()).await.unwrap();
        let mut got = [0u8; 6];
        b.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"$OUT\r\n");
        drop(b);
        assert_eq!(
            link.recv().await.unwrap_err().kind(),
            io::ErrorKind::UnexpectedEof
        );
    }

    #[test]
    fn a_splitter_takes_cr_or_lf_skips_empty_lines_and_bounds_them() {
        let mut lines = LineSplitter::new(8);
        assert_eq!(lines.push(b"one\r\ntw"), vec![b"one".to_vec()]);
        assert_eq!(lines.push(b"o\n\n\rthree"), vec![b"two".to_vec()]);
        assert_eq!(lines.push(b"3456789"), vec![b"three345".to_vec()]);
        lines.clear();
        assert!(lines.push(b"\r\n").is_empty());
    }

    #[tokio::test]
    async fn bounds_a_line_without_delimiter() {
        let (a, mut b) = tokio::io::duplex(MAX_LINE * 2);
        let mut link = LineLink::new(a, b"\n");
        b.write_all(&vec![b'x'; MAX_LINE + 10]).await.unwrap();
        let (line, ()) = link.recv().await.unwrap();
        assert!(line.len() >= MAX_LINE && line.len() <= MAX_LINE + 512);
    }
}
