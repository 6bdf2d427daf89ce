//! Vehicle addresses as the user writes them: `udpout:HOST:PORT`,
//! `udpin:HOST:PORT`, `tcpout:HOST:PORT` or `serial:DEVICE:BAUD` (the
//! forms MAVProxy and the `mavlink` crate use), checked before any socket
//! is opened so a typo is bad input rather than a link failure.

use std::fmt;

/// A checked vehicle address.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VehicleAddress {
    /// Send to a vehicle listening on HOST:PORT (UDP).
    UdpOut { host: String, port: u16 },
    /// Listen on HOST:PORT and answer whoever sends (UDP): the vehicle
    /// must speak first (a HEARTBEAT).
    UdpIn { host: String, port: u16 },
    /// Connect to a vehicle (or a TCP bridge) on HOST:PORT.
    TcpOut { host: String, port: u16 },
    /// A serial device at a baud rate.
    Serial { device: String, baud: u32 },
}

enum Kind {
    UdpOut,
    UdpIn,
    TcpOut,
    Serial,
}

/// Why an address was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("bad vehicle address {address:?}: {why}")]
pub struct AddressError {
    pub address: String,
    pub why: String,
}

impl VehicleAddress {
    /// Parse `KIND:HOST:PORT` / `serial:DEVICE:BAUD`. Hosts may be names,
    /// IPv4 or bracketed IPv6 (`udpout:[::1]:14550`); the host is not
    /// resolved here.
    pub fn parse(text: &str) -> Result<VehicleAddress, AddressError> {
        let fail = |why: &str| AddressError {
            address: text.to_string(),
            why: why.to_string(),
        };
        let (kind, rest) = text.split_once(':').ok_or_else(|| {
            fail("expected udpout:HOST:PORT, udpin:HOST:PORT, tcpout:HOST:PORT or serial:DEVICE:BAUD")
        })?;
        let kind = match kind {
            "udpout" => Kind::UdpOut,
            "udpin" => Kind::UdpIn,
            "tcpout" => Kind::TcpOut,
            "serial" => Kind::Serial,
            other => {
                return Err(fail(&format!(
                    "unknown link kind {other:?} (udpout, udpin, tcpout or serial)"
                )));
            }
        };
        // The last colon separates the port or baud rate (device paths
        // and IPv6 hosts have their own).
        let (head, tail) = rest
            .rsplit_once(':')
            .ok_or_else(|| fail("missing :PORT (or :BAUD for serial)"))?;
        if head.is_empty() {
            return Err(fail("missing host (or device)"));
        }
        if head.chars().any(|c| c.is_whitespace() || c.is_control()) {
            return Err(fail(
                "the host (or device) contains spaces or control characters",
            ));
        }
        let port = || -> Result<u16, AddressError> {
            match tail.parse::<u16>() {
                Ok(p) if p > 0 => Ok(p),
                _ => Err(fail("the port must be a number from 1 to 65535")),
            }
        };
        let host = || -> Result<String, AddressError> {
            let h = head.strip_prefix('[').map_or(Ok(head), |inner| {
                inner
                    .strip_suffix(']')
                    .ok_or_else(|| fail("unclosed [ in an IPv6 host"))
            })?;
            if h.is_empty() {
                return Err(fail("missing host"));
            }
            if h.contains(':') && !head.starts_with('[') {
                return Err(fail("write an IPv6 host in brackets: [::1]:PORT"));
            }
            Ok(h.to_string())
        };
        match kind {
            Kind::UdpOut => Ok(VehicleAddress::UdpOut {
                host: host()?,
                port: port()?,
            }),
            Kind::UdpIn => Ok(VehicleAddress::UdpIn {
                host: host()?,
                port: port()?,
            }),
            Kind::TcpOut => Ok(VehicleAddress::TcpOut {
                host: host()?,
                port: port()?,
            }),
            Kind::Serial => match tail.parse::<u32>() {
                Ok(baud) if baud > 0 => Ok(VehicleAddress::Serial {
                    device: head.to_string(),
                    baud,
                }),
                _ => Err(fail("the baud rate must be a positive number")),
            },
        }
    }

    /// The address in the `mavlink` crate's `connect` syntax.
    pub fn connect_string(&self) -> String {
        match self {
            VehicleAddress::UdpOut { host, port } => format!("udpout:{}:{port}", bracket(host)),
            VehicleAddress::UdpIn { host, port } => format!("udpin:{}:{port}", bracket(host)),
            VehicleAddress::TcpOut { host, port } => format!("tcpout:{}:{port}", bracket(host)),
            VehicleAddress::Serial { device, baud } => format!("serial:{device}:{baud}"),
        }
    }
}

/// The canonical text (the same as `connect_string`), used to match
/// addresses against the service's allow-list.
impl fmt::Display for VehicleAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.connect_string())
    }
}

fn bracket(host: &str) -> String {
    if host.contains(':') {
        format!("[{host}]")
    } else {
        host.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_kind() {
        assert_eq!(
            VehicleAddress::parse("udpout:127.0.0.1:14550"),
            Ok(VehicleAddress::UdpOut {
                host: "127.0.0.1".into(),
                port: 14550
            })
        );
        assert_eq!(
            VehicleAddress::parse("udpin:0.0.0.0:14551").map(|a| a.to_string()),
            Ok("udpin:0.0.0.0:14551".into())
        );
        assert_eq!(
            VehicleAddress::parse("tcpout:localhost:5760").map(|a| a.to_string()),
            Ok("tcpout:localhost:5760".into())
        );
        assert_eq!(
            VehicleAddress::parse("serial:/dev/ttyACM0:115200"),
            Ok(VehicleAddress::Serial {
                device: "/dev/ttyACM0".into(),
                baud: 115200
            })
        );
        assert_eq!(
            VehicleAddress::parse("udpout:[::1]:14550").map(|a| a.to_string()),
            Ok("udpout:[::1]:14550".into())
        );
    }

    #[test]
    fn refuses_bad_addresses_naming_the_fault() {
        for (text, why) in [
            ("127.0.0.1:14550", "unknown link kind"),
            ("udp:127.0.0.1:14550", "unknown link kind"),
            ("udpout:127.0.0.1", "missing :PORT"),
            ("udpout:127.0.0.1:0", "1 to 65535"),
            ("udpout:127.0.0.1:70000", "1 to 65535"),
            ("udpout::14550", "missing host"),
            ("tcpout:::1:5760", "brackets"),
            ("serial:/dev/ttyUSB0:fast", "baud rate"),
            ("udpout:a b:1", "spaces"),
            ("nonsense", "expected udpout"),
        ] {
            let e = VehicleAddress::parse(text).expect_err(text);
            assert!(e.to_string().contains(why), "{text}: {e}");
        }
    }
}
