//! `HOST[:PORT]` addresses on the command line.

/// `HOST`, `HOST:PORT`, `[V6]` or `[V6]:PORT` as host and port
/// (`default_port` when left out); `None` when it is none of these or the
/// port is not 1 to 65535.
pub(crate) fn host_port(address: &str, default_port: u16) -> Option<(String, u16)> {
    let address = address.trim();
    let (host, port) = match address.strip_prefix('[') {
        Some(rest) => {
            let (host, tail) = rest.split_once(']')?;
            match tail {
                "" => (host, None),
                tail => (host, Some(tail.strip_prefix(':')?)),
            }
        }
        None => match address.split_once(':') {
            Some((host, port)) => (host, Some(port)),
            None => (address, None),
        },
    };
    if host.is_empty() || host.contains(char::is_whitespace) {
        return None;
    }
    let port = match port {
        None => default_port,
        Some(port) => port.parse().ok().filter(|&p| p != 0)?,
    };
    Some((host.to_string(), port))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_address_without_a_port_is_on_the_default_port() {
        let at = |h: &str, p| Some((h.to_string(), p));
        assert_eq!(host_port("localhost", 1883), at("localhost", 1883));
        assert_eq!(host_port("10.0.0.1:1884", 1883), at("10.0.0.1", 1884));
        assert_eq!(host_port("[::1]", 9000), at("::1", 9000));
        assert_eq!(host_port("[::1]:1999", 1883), at("::1", 1999));
        for bad in [
            "",
            ":1883",
            "host:",
            "host:port",
            "host:99999",
            "host:0",
            "[::1",
            "[::1]x",
            "a b",
        ] {
            assert_eq!(host_port(bad, 1883), None, "{bad:?}");
        }
    }
}
