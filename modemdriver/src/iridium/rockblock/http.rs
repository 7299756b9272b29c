//! The HTTP/1.1 client of the RockBLOCK web service's two ends: one POST
//! per connection (the shore's MT messages, the emulated service's MO
//! webhook calls), over TCP, or over TLS (rustls, feature `rockblock-tls`)
//! for an `https://` server.

use std::fmt;
use std::time::Duration;

use http_body_util::{BodyExt, Full, Limited};
use hyper::body::Bytes;
use hyper::header::{CONNECTION, CONTENT_TYPE, HOST, USER_AGENT};
use hyper::Request;
use hyper_util::rt::TokioIo;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpStream;

/// Largest response body read (the service answers with a short line).
pub const MAX_RESPONSE_BYTES: usize = 64 * 1024;

/// Whether this build speaks HTTPS (feature `rockblock-tls`).
pub const HTTPS_SUPPORTED: bool = cfg!(feature = "rockblock-tls");

/// Where a POST goes: `http[s]://HOST[:PORT]` and a path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HttpUrl {
    /// HTTPS (TLS) rather than plain HTTP.
    pub tls: bool,
    /// Host name or address (an IPv6 address without brackets).
    pub host: String,
    /// TCP port (80 or 443 unless given).
    pub port: u16,
    /// The path, from `/` (with its query, if any).
    pub path: String,
}

impl HttpUrl {
    /// The URL of `server` (`https://rockblock.rock7.com`,
    /// `http://127.0.0.1:8081`, or a bare `HOST:PORT`, taken as plain HTTP
    /// as Goby3's HTTP client takes it) and `endpoint` (a path:
    /// `/rockblock/MT`; a path in `server` comes before it).
    pub fn parse(server: &str, endpoint: &str) -> Result<HttpUrl, String> {
        let server = server.trim();
        let (tls, rest) = if let Some(r) = server.strip_prefix("https://") {
            (true, r)
        } else if let Some(r) = server.strip_prefix("http://") {
            (false, r)
        } else if server.contains("://") {
            return Err(format!(
                "{server:?}: only http:// and https:// servers are known"
            ));
        } else {
            (false, server)
        };
        let (authority, base_path) = match rest.find('/') {
            Some(i) => (&rest[..i], rest[i..].trim_end_matches('/')),
            None => (rest, ""),
        };
        if authority.is_empty() {
            return Err(format!("{server:?} names no host"));
        }
        if authority.contains('@') {
            return Err(format!(
                "{server:?}: credentials belong in username and password, not in the server"
            ));
        }
        let default_port = if tls { 443 } else { 80 };
        let (host, port) = if let Some(v6) = authority.strip_prefix('[') {
            let (h, after) = v6
                .split_once(']')
                .ok_or_else(|| format!("{server:?}: an IPv6 address without its closing ]"))?;
            let port = match after.strip_prefix(':') {
                Some(p) => parse_port(p, server)?,
                None if after.is_empty() => default_port,
                None => return Err(format!("{server:?}: {after:?} after the address")),
            };
            (h.to_string(), port)
        } else {
            match authority.rsplit_once(':') {
                Some((h, p)) => (h.to_string(), parse_port(p, server)?),
                None => (authority.to_string(), default_port),
            }
        };
        if host.is_empty() {
            return Err(format!("{server:?} names no host"));
        }
        let endpoint = endpoint.trim();
        let path = match (base_path, endpoint) {
            ("", "") => "/".to_string(),
            (b, "") => b.to_string(),
            (b, e) if e.starts_with('/') => format!("{b}{e}"),
            (b, e) => format!("{b}/{e}"),
        };
        Ok(HttpUrl {
            tls,
            host,
            port,
            path,
        })
    }

    /// The `Host` header's value.
    fn host_header(&self) -> String {
        let host = if self.host.contains(':') {
            format!("[{}]", self.host)
        } else {
            self.host.clone()
        };
        if self.port == if self.tls { 443 } else { 80 } {
            host
        } else {
            format!("{host}:{}", self.port)
        }
    }
}

fn parse_port(p: &str, server: &str) -> Result<u16, String> {
    p.parse::<u16>()
        .ok()
        .filter(|&p| p > 0)
        .ok_or_else(|| format!("{server:?}: {p:?} is not a TCP port"))
}

impl fmt::Display for HttpUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}://{}{}",
            if self.tls { "https" } else { "http" },
            self.host_header(),
            self.path
        )
    }
}

/// An HTTP response.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HttpReply {
    /// Its status code.
    pub status: u16,
    /// Its body (at most [`MAX_RESPONSE_BYTES`]).
    pub body: Vec<u8>,
}

/// Why a POST got no answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PostError {
    /// What failed (no connection, TLS, no answer in time, a broken
    /// response).
    pub message: String,
    /// The request never left: no connection, or no TLS session, was made.
    /// Otherwise the server may have it, and may have acted on it.
    pub unsent: bool,
}

impl PostError {
    fn not_sent(message: String) -> Self {
        PostError {
            message,
            unsent: true,
        }
    }

    fn maybe_taken(message: String) -> Self {
        PostError {
            message,
            unsent: false,
        }
    }
}

impl fmt::Display for PostError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// POSTs `body` to `url` and reads the response, all within `timeout`.
///
/// # Errors
/// What failed, and whether the request left ([`PostError::unsent`]).
pub async fn post(
    url: &HttpUrl,
    content_type: &str,
    body: Vec<u8>,
    timeout: Duration,
) -> Result<HttpReply, PostError> {
    let deadline = tokio::time::Instant::now() + timeout;
    let late = || format!("no answer from {url} in {} ms", timeout.as_millis());
    let tcp =
        match tokio::time::timeout_at(deadline, TcpStream::connect((url.host.as_str(), url.port)))
            .await
        {
            Err(_) => return Err(PostError::not_sent(late())),
            Ok(Err(e)) => return Err(PostError::not_sent(format!("cannot reach {url}: {e}"))),
            Ok(Ok(tcp)) => tcp,
        };
    let _ = tcp.set_nodelay(true);
    if url.tls {
        #[cfg(feature = "rockblock-tls")]
        {
            let tls = match tokio::time::timeout_at(deadline, tls::connect(&url.host, tcp)).await {
                Err(_) => return Err(PostError::not_sent(late())),
                Ok(Err(e)) => return Err(PostError::not_sent(format!("TLS with {url}: {e}"))),
                Ok(Ok(tls)) => tls,
            };
            return tokio::time::timeout_at(deadline, exchange(url, tls, content_type, body))
                .await
                .unwrap_or_else(|_| Err(PostError::maybe_taken(late())));
        }
        #[cfg(not(feature = "rockblock-tls"))]
        {
            drop(tcp);
            return Err(PostError::not_sent(format!(
                "{url}: HTTPS is not in this build (build with the feature rockblock-tls)"
            )));
        }
    }
    tokio::time::timeout_at(deadline, exchange(url, tcp, content_type, body))
        .await
        .unwrap_or_else(|_| Err(PostError::maybe_taken(late())))
}

async fn exchange<IO>(
    url: &HttpUrl,
    io: IO,
    content_type: &str,
    body: Vec<u8>,
) -> Result<HttpReply, PostError>
where
    IO: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    // Header names as written in the RFCs' examples (Content-Length):
    // Goby3's RockBLOCK webhook reads them case-sensitively.
    let (mut sender, connection) = hyper::client::conn::http1::Builder::new()
        .title_case_headers(true)
        .handshake(TokioIo::new(io))
        .await
        .map_err(|e| PostError::not_sent(format!("HTTP with {url}: {e}")))?;
    let request = Request::post(url.path.as_str())
        .header(HOST, url.host_header())
        .header(CONTENT_TYPE, content_type)
        .header(
            USER_AGENT,
            concat!("goby-modemdriver/", env!("CARGO_PKG_VERSION")),
        )
        .header(CONNECTION, "close")
        .body(Full::new(Bytes::from(body)))
        .map_err(|e| PostError::not_sent(format!("HTTP request to {url}: {e}")))?;
    // From here on the request may have left.
    let exchange = async {
        let response = sender
            .send_request(request)
            .await
            .map_err(|e| PostError::maybe_taken(format!("HTTP with {url}: {e}")))?;
        let status = response.status().as_u16();
        let body = Limited::new(response.into_body(), MAX_RESPONSE_BYTES)
            .collect()
            .await
            .map_err(|e| PostError::maybe_taken(format!("HTTP response from {url}: {e}")))?
            .to_bytes()
            .to_vec();
        Ok(HttpReply { status, body })
    };
    // The connection is driven while the exchange runs. It may end first
    // (the server closes after its answer): the answer is then read from
    // what the connection passed on.
    let mut exchange = std::pin::pin!(exchange);
    tokio::select! {
        biased;
        reply = &mut exchange => reply,
        ended = connection => match ended {
            Ok(()) => exchange.await,
            Err(e) => Err(PostError::maybe_taken(format!("HTTP with {url}: {e}"))),
        },
    }
}

#[cfg(feature = "rockblock-tls")]
mod tls {
    use std::sync::{Arc, OnceLock};

    use tokio::net::TcpStream;
    use tokio_rustls::rustls::pki_types::ServerName;
    use tokio_rustls::rustls::{ClientConfig, RootCertStore};
    use tokio_rustls::{client::TlsStream, TlsConnector};

    /// The system's root certificates, read once.
    fn config() -> Result<Arc<ClientConfig>, String> {
        static CONFIG: OnceLock<Result<Arc<ClientConfig>, String>> = OnceLock::new();
        CONFIG
            .get_or_init(|| {
                let mut roots = RootCertStore::empty();
                let found = rustls_native_certs::load_native_certs();
                for cert in found.certs {
                    let _ = roots.add(cert);
                }
                if roots.is_empty() {
                    return Err(format!(
                        "no root certificates found on this system ({} errors reading them)",
                        found.errors.len()
                    ));
                }
                Ok(Arc::new(
                    ClientConfig::builder()
                        .with_root_certificates(roots)
                        .with_no_client_auth(),
                ))
            })
            .clone()
    }

    pub(super) async fn connect(
        host: &str,
        tcp: TcpStream,
    ) -> Result<TlsStream<TcpStream>, String> {
        let name = ServerName::try_from(host.to_string()).map_err(|e| format!("{host:?}: {e}"))?;
        TlsConnector::from(config()?)
            .connect(name, tcp)
            .await
            .map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn servers_and_endpoints_make_urls() {
        let u = HttpUrl::parse("https://rockblock.rock7.com", "/rockblock/MT").unwrap();
        assert_eq!(
            (u.tls, u.host.as_str(), u.port, u.path.as_str()),
            (true, "rockblock.rock7.com", 443, "/rockblock/MT")
        );
        assert_eq!(u.to_string(), "https://rockblock.rock7.com/rockblock/MT");
        let u = HttpUrl::parse("127.0.0.1:8081", "/rockblock/MT").unwrap();
        assert_eq!((u.tls, u.port), (false, 8081));
        assert_eq!(u.to_string(), "http://127.0.0.1:8081/rockblock/MT");
        let u = HttpUrl::parse("http://[::1]:9/base/", "mt").unwrap();
        assert_eq!(
            (u.host.as_str(), u.port, u.path.as_str()),
            ("::1", 9, "/base/mt")
        );
        assert_eq!(u.to_string(), "http://[::1]:9/base/mt");
        assert_eq!(HttpUrl::parse("http://h", "").unwrap().path, "/");
        for (bad, says) in [
            ("ftp://h", "only http"),
            ("http://", "no host"),
            ("http://h:0", "not a TCP port"),
            ("http://h:x", "not a TCP port"),
            ("http://u:p@h", "credentials"),
            ("http://[::1", "closing"),
        ] {
            let e = HttpUrl::parse(bad, "/").unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[tokio::test]
    async fn a_post_and_its_answer_over_a_real_socket() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let server = tokio::spawn(async move {
            let (mut s, _) = listener.accept().await.unwrap();
            let mut got = Vec::new();
            let mut buf = [0u8; 1024];
            while !String::from_utf8_lossy(&got).contains("a=1") {
                let n = s.read(&mut buf).await.unwrap();
                assert!(n > 0);
                got.extend_from_slice(&buf[..n]);
            }
            s.write_all(b"HTTP/1.1 200 OK\r\nContent-Length: 6\r\n\r\nOK,123")
                .await
                .unwrap();
            String::from_utf8(got).unwrap()
        });
        let url = HttpUrl::parse(&format!("127.0.0.1:{port}"), "/rockblock/MT").unwrap();
        let reply = post(
            &url,
            "application/x-www-form-urlencoded",
            b"a=1".to_vec(),
            Duration::from_secs(5),
        )
        .await
        .unwrap();
        assert_eq!((reply.status, reply.body.as_slice()), (200, &b"OK,123"[..]));
        let request = server.await.unwrap();
        assert!(
            request.starts_with("POST /rockblock/MT HTTP/1.1\r\n"),
            "{request}"
        );
        assert!(
            request.contains(&format!("Host: 127.0.0.1:{port}\r\n")),
            "{request}"
        );
        assert!(request.contains("Content-Length: 3\r\n"), "{request}");
        // Nobody there.
        drop(url);
        let closed = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = closed.local_addr().unwrap();
        drop(closed);
        let url = HttpUrl::parse(&format!("http://{addr}"), "/").unwrap();
        let e = post(&url, "text/plain", Vec::new(), Duration::from_secs(5))
            .await
            .unwrap_err();
        assert!(e.message.contains("cannot reach"), "{e}");
        assert!(e.unsent, "nothing left: {e:?}");
    }
}
