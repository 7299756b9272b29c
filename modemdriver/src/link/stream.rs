//! A modem's byte stream: a TCP connection or a serial line (a serial
//! port, a USB adapter, a pseudo-terminal), opened from where it is
//! ([`Endpoint`]) and read as lines or as bytes ([`StreamLink`]).

use std::io;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::line::LineLink;
use super::Link;

/// A byte stream to a modem.
pub trait Stream: AsyncRead + AsyncWrite + Unpin + Send {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send> Stream for T {}

/// A boxed byte stream to a modem.
pub type BoxStream = Box<dyn Stream>;

/// Longest a TCP connection attempt waits.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// Where a modem is, to reach it (again).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// A TCP server (the modem's Ethernet interface, or a serial server),
    /// `host:port`.
    Tcp(String),
    /// A serial line (or pseudo-terminal), 8N1 without flow control.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
        /// Raise DTR once open (an Iridium transceiver's `AT&D2`).
        dtr: bool,
    },
}

impl Endpoint {
    /// A serial line at `baud`, DTR left alone.
    pub fn serial(path: impl Into<String>, baud: u32) -> Endpoint {
        Endpoint::Serial {
            path: path.into(),
            baud,
            dtr: false,
        }
    }

    /// Opens the link.
    ///
    /// # Errors
    /// What the connection or the device says; a TCP server that does not
    /// answer within [`CONNECT_TIMEOUT`] is `TimedOut`.
    pub async fn open(&self) -> io::Result<BoxStream> {
        match self {
            Endpoint::Tcp(addr) => {
                let stream =
                    tokio::time::timeout(CONNECT_TIMEOUT, tokio::net::TcpStream::connect(addr))
                        .await
                        .map_err(|_| {
                            io::Error::new(
                                io::ErrorKind::TimedOut,
                                format!("no connection to {addr} within {CONNECT_TIMEOUT:?}"),
                            )
                        })??;
                let _ = stream.set_nodelay(true);
                Ok(Box::new(stream))
            }
            Endpoint::Serial { .. } => self.open_serial(),
        }
    }

    /// Opens a serial line at once (it needs no waiting; a TCP endpoint is
    /// opened with [`open`](Self::open)). Within a tokio runtime.
    ///
    /// # Errors
    /// What the device says; `Unsupported` for a TCP endpoint.
    pub fn open_serial(&self) -> io::Result<BoxStream> {
        use tokio_serial::{SerialPort, SerialPortBuilderExt};
        let Endpoint::Serial { path, baud, dtr } = self else {
            return Err(io::Error::new(
                io::ErrorKind::Unsupported,
                format!("{} is not a serial line", self.describe()),
            ));
        };
        let mut stream = tokio_serial::new(path, *baud)
            .open_native_async()
            .map_err(|e| io::Error::other(format!("cannot open serial port {path}: {e}")))?;
        if *dtr {
            // A pseudo-terminal has no DTR line: not an error.
            let _ = stream.write_data_terminal_ready(true);
        }
        Ok(Box::new(stream))
    }

    /// Where, in words: `tcp 192.168.0.209:9200`, `/dev/ttyUSB0`.
    pub fn describe(&self) -> String {
        match self {
            Endpoint::Tcp(a) => format!("tcp {a}"),
            Endpoint::Serial { path, .. } => path.clone(),
        }
    }
}

/// How a driver reads its modem's stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Units {
    /// Lines ended by this delimiter (empty: `\r\n`), which writes add.
    Lines(Vec<u8>),
    /// The bytes of each read, written as they are.
    Bytes,
}

/// A byte stream as the bytes of each read.
#[derive(Debug)]
pub struct ByteLink<S> {
    stream: S,
}

impl<S> ByteLink<S> {
    /// Wraps `stream`.
    pub fn new(stream: S) -> Self {
        ByteLink { stream }
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin + Send> Link for ByteLink<S> {
    type Peer = ();

    async fn recv(&mut self) -> io::Result<(Vec<u8>, ())> {
        let mut buf = vec![0u8; 2048];
        // `read` is cancel-safe: bytes are only taken once it completes.
        let n = self.stream.read(&mut buf).await?;
        if n == 0 {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the device closed",
            ));
        }
        buf.truncate(n);
        Ok((buf, ()))
    }

    async fn send(&mut self, unit: &[u8], _peer: &()) -> io::Result<()> {
        self.stream.write_all(unit).await?;
        self.stream.flush().await
    }
}

/// A modem's stream read as lines or as bytes ([`Units`]).
#[derive(Debug)]
pub enum StreamLink {
    /// Lines.
    Lines(LineLink<BoxStream>),
    /// Bytes.
    Bytes(ByteLink<BoxStream>),
}

impl StreamLink {
    /// `stream` read as `units` say.
    pub fn new(stream: BoxStream, units: &Units) -> StreamLink {
        match units {
            Units::Lines(delimiter) => StreamLink::Lines(LineLink::new(stream, delimiter)),
            Units::Bytes => StreamLink::Bytes(ByteLink::new(stream)),
        }
    }
}

impl Link for StreamLink {
    type Peer = ();

    async fn recv(&mut self) -> io::Result<(Vec<u8>, ())> {
        match self {
            StreamLink::Lines(l) => l.recv().await,
            StreamLink::Bytes(b) => b.recv().await,
        }
    }

    async fn send(&mut self, unit: &[u8], peer: &()) -> io::Result<()> {
        match self {
            StreamLink::Lines(l) => l.send(unit, peer).await,
            StreamLink::Bytes(b) => b.send(unit, peer).await,
        }
    }
}

impl std::fmt::Debug for dyn Stream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Stream")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn bytes_are_read_as_they_come_and_written_as_they_are() {
        let (a, mut b) = tokio::io::duplex(1024);
        let mut link = StreamLink::new(Box::new(a), &Units::Bytes);
        b.write_all(b"+++AT\r\nhalf").await.unwrap();
        assert_eq!(link.recv().await.unwrap().0, b"+++AT\r\nhalf");
        link.send(b"ATO", &()).await.unwrap();
        let mut got = [0u8; 3];
        b.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"ATO");
        drop(b);
        assert_eq!(
            link.recv().await.unwrap_err().kind(),
            io::ErrorKind::UnexpectedEof
        );
    }

    #[tokio::test]
    async fn a_tcp_endpoint_opens_and_is_told() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let endpoint = Endpoint::Tcp(listener.local_addr().unwrap().to_string());
        assert!(endpoint.describe().starts_with("tcp 127.0.0.1:"));
        let mut stream = endpoint.open().await.unwrap();
        let (mut served, _) = listener.accept().await.unwrap();
        stream.write_all(b"x").await.unwrap();
        let mut got = [0u8; 1];
        served.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"x");
        assert!(Endpoint::serial("/no/such/tty", 9600).open().await.is_err());
    }
}
