//! Lines over a byte stream (serial port, TCP, pseudo-terminal).

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

    #[tokio::test]
    async fn bounds_a_line_without_delimiter() {
        let (a, mut b) = tokio::io::duplex(MAX_LINE * 2);
        let mut link = LineLink::new(a, b"\n");
        b.write_all(&vec![b'x'; MAX_LINE + 10]).await.unwrap();
        let (line, ()) = link.recv().await.unwrap();
        assert!(line.len() >= MAX_LINE && line.len() <= MAX_LINE + 512);
    }
}
