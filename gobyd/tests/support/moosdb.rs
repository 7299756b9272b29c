//! A real MOOSDB (the MOOS core's) on a free loopback port, when one is on
//! the PATH; killed when dropped.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use super::daemon::free_tcp_port;

/// MOOSDB on the PATH (put the MOOS core's `bin` directory there).
pub fn moosdb_on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("MOOSDB"))
        .find(|p| p.is_file())
}

/// A running MOOSDB.
pub struct RealMoosDb {
    child: Child,
    /// Its port on 127.0.0.1.
    pub port: u16,
}

impl RealMoosDb {
    /// Starts `exe` in `dir` on a free port, for `community`.
    pub fn start(exe: &Path, dir: &Path, community: &str) -> RealMoosDb {
        let port = free_tcp_port();
        let audit = UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Command::new(exe)
            .arg(format!("--moos_port={port}"))
            .arg(format!("--moos_community={community}"))
            .arg("--moos_suicide_disable")
            .arg(format!("--audit_port={audit}"))
            .arg("--moos_no_colour")
            .current_dir(dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("MOOSDB starts");
        RealMoosDb { child, port }
    }
}

impl Drop for RealMoosDb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
