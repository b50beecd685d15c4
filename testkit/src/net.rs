//! Free loopback ports, for Zenoh sessions and servers that must not meet other tests' traffic.

use crate::{Error, Result};

/// A loopback TCP port nothing listens on right now (the OS picks it; another process could
/// take it before it is bound again, which in practice it does not).
pub fn free_port() -> Result<u16> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(Error::Port)
}

/// The Zenoh endpoint `tcp/127.0.0.1:<port>`.
pub fn loopback_endpoint(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

/// A Zenoh endpoint on a free loopback port (for tests).
///
/// # Panics
/// When no port can be bound.
pub fn free_endpoint() -> String {
    loopback_endpoint(free_port().unwrap_or_else(|e| panic!("{e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_free_port_can_be_bound() {
        // Another process may take a port between the probe and the bind (CI once saw it):
        // the contract is that a returned port is nearly always bindable, so one of a few is.
        let bound = (0..5).any(|_| {
            let port = free_port().expect("a free port");
            port != 0 && std::net::TcpListener::bind(("127.0.0.1", port)).is_ok()
        });
        assert!(bound, "none of five probed ports could be bound again");
        assert!(free_endpoint().starts_with("tcp/127.0.0.1:"));
    }
}
