//! Loopback endpoints for a bridge to listen on when the whole fleet runs on one machine
//! (`fleet run --hosts N`, and the ipc benchmark's router).

/// What a bridge listens with on the loopback.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// Plain TCP (`--insecure-links`), and TLS over TCP.
    Tcp,
    /// UDP, for QUIC.
    Udp,
}

/// A loopback port of `transport` that nothing uses now, for a bridge to listen on.
pub fn free_loopback_port(transport: Transport) -> std::io::Result<u16> {
    let address = ("127.0.0.1", 0);
    let bound = match transport {
        Transport::Tcp => std::net::TcpListener::bind(address).and_then(|l| l.local_addr()),
        Transport::Udp => std::net::UdpSocket::bind(address).and_then(|s| s.local_addr()),
    };
    Ok(bound?.port())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_free_port_is_found_for_each_transport() {
        for transport in [Transport::Tcp, Transport::Udp] {
            let port = free_loopback_port(transport).expect("a free port");
            assert_ne!(port, 0);
        }
    }
}
