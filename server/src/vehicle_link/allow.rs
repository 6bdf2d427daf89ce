//! The vehicle links the service may reach (`serve --vehicle-links`): each
//! entry an exact address (`udpout:127.0.0.1:14550`) or an address whose
//! port — or baud rate, for `serial:` — is any (`*`) or a range
//! (`14550-14560`). Hosts and devices are always named exactly: the service
//! never relays to an address its operator did not list.

use std::fmt;

use super::address::VehicleAddress;

/// Which ports (or baud rates) an entry allows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ports {
    Any,
    Range(u32, u32),
}

/// One entry of the allow-list: an address with its port given as one
/// number, a range or `*`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinkPattern {
    /// The address with the first allowed port, for its kind and host.
    base: VehicleAddress,
    ports: Ports,
}

/// Why an allow-list entry was refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("bad vehicle link {text:?}: {why}")]
pub struct PatternError {
    pub text: String,
    pub why: String,
}

impl LinkPattern {
    /// Parse `KIND:HOST:PORT`, `KIND:HOST:LO-HI` or `KIND:HOST:*` (and
    /// `serial:DEVICE:BAUD|*`); the address syntax is
    /// [`VehicleAddress::parse`]'s.
    pub fn parse(text: &str) -> Result<LinkPattern, PatternError> {
        let text = text.trim();
        let fail = |why: String| PatternError {
            text: text.to_string(),
            why,
        };
        let (head, tail) = text.rsplit_once(':').ok_or_else(|| {
            fail("expected KIND:HOST:PORT, with the port a number, LO-HI or *".into())
        })?;
        let (first, ports) = if tail == "*" {
            ("1".to_string(), Ports::Any)
        } else if let Some((lo, hi)) = tail.split_once('-') {
            let num = |s: &str| s.parse::<u32>().ok().filter(|&n| n > 0);
            match (num(lo), num(hi)) {
                (Some(lo), Some(hi)) if lo <= hi => (lo.to_string(), Ports::Range(lo, hi)),
                _ => {
                    return Err(fail(format!(
                        "port range {tail:?}: expected LO-HI, two numbers from 1 with LO <= HI"
                    )));
                }
            }
        } else {
            (tail.to_string(), Ports::Any)
        };
        let base =
            VehicleAddress::parse(&format!("{head}:{first}")).map_err(|e| fail(e.why.clone()))?;
        if let VehicleAddress::UdpOut { host, .. }
        | VehicleAddress::UdpIn { host, .. }
        | VehicleAddress::TcpOut { host, .. } = &base
            && host.contains('*')
        {
            return Err(fail(
                "hosts are named exactly (no wildcards): the service must not relay to any host"
                    .into(),
            ));
        }
        if let Ports::Range(_, hi) = ports
            && !matches!(base, VehicleAddress::Serial { .. })
            && hi > u32::from(u16::MAX)
        {
            return Err(fail("ports go up to 65535".into()));
        }
        // A single number: exactly that port (checked by the parse above).
        let ports = match (tail, ports) {
            ("*", _) | (_, Ports::Range(..)) => ports,
            _ => {
                let n = port_of(&base);
                Ports::Range(n, n)
            }
        };
        Ok(LinkPattern { base, ports })
    }

    /// Whether `address` is one this entry allows: the same kind, the
    /// same host (names compared without case) or device, a port (baud
    /// rate) in its range.
    pub fn allows(&self, address: &VehicleAddress) -> bool {
        use VehicleAddress::*;
        let same_place = match (&self.base, address) {
            (UdpOut { host: a, .. }, UdpOut { host: b, .. })
            | (UdpIn { host: a, .. }, UdpIn { host: b, .. })
            | (TcpOut { host: a, .. }, TcpOut { host: b, .. }) => a.eq_ignore_ascii_case(b),
            (Serial { device: a, .. }, Serial { device: b, .. }) => a == b,
            _ => false,
        };
        let port = port_of(address);
        same_place
            && match self.ports {
                Ports::Any => true,
                Ports::Range(lo, hi) => (lo..=hi).contains(&port),
            }
    }

    /// The entry names exactly one address (no `*`, no range).
    pub fn is_exact(&self) -> bool {
        matches!(self.ports, Ports::Range(lo, hi) if lo == hi)
    }
}

fn port_of(address: &VehicleAddress) -> u32 {
    match address {
        VehicleAddress::UdpOut { port, .. }
        | VehicleAddress::UdpIn { port, .. }
        | VehicleAddress::TcpOut { port, .. } => u32::from(*port),
        VehicleAddress::Serial { baud, .. } => *baud,
    }
}

/// The entry in its canonical form: `udpout:127.0.0.1:14550`,
/// `udpout:127.0.0.1:14550-14560`, `tcpout:[::1]:*`.
impl fmt::Display for LinkPattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = self.base.connect_string();
        let head = text.rsplit_once(':').map_or(text.as_str(), |(h, _)| h);
        match self.ports {
            Ports::Any => write!(f, "{head}:*"),
            Ports::Range(lo, hi) if lo == hi => write!(f, "{head}:{lo}"),
            Ports::Range(lo, hi) => write!(f, "{head}:{lo}-{hi}"),
        }
    }
}

/// `--vehicle-links`' value parser.
pub fn parse_link_pattern(text: &str) -> Result<LinkPattern, String> {
    LinkPattern::parse(text).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(s: &str) -> VehicleAddress {
        VehicleAddress::parse(s).unwrap()
    }

    #[test]
    fn exact_entries_allow_that_address_only() {
        let p = LinkPattern::parse("udpout:127.0.0.1:14550").unwrap();
        assert!(p.is_exact());
        assert!(p.allows(&addr("udpout:127.0.0.1:14550")));
        assert!(!p.allows(&addr("udpout:127.0.0.1:14551")));
        assert!(!p.allows(&addr("udpout:127.0.0.2:14550")));
        assert!(!p.allows(&addr("tcpout:127.0.0.1:14550")));
        assert!(!p.allows(&addr("udpin:127.0.0.1:14550")));
        assert_eq!(p.to_string(), "udpout:127.0.0.1:14550");
    }

    #[test]
    fn ranges_and_any_port() {
        let r = LinkPattern::parse("udpout:127.0.0.1:14550-14560").unwrap();
        assert!(!r.is_exact());
        assert!(r.allows(&addr("udpout:127.0.0.1:14550")));
        assert!(r.allows(&addr("udpout:127.0.0.1:14560")));
        assert!(!r.allows(&addr("udpout:127.0.0.1:14561")));
        assert!(!r.allows(&addr("udpout:127.0.0.1:14549")));
        assert_eq!(r.to_string(), "udpout:127.0.0.1:14550-14560");
        let any = LinkPattern::parse("tcpout:[::1]:*").unwrap();
        assert!(any.allows(&addr("tcpout:[::1]:5760")));
        assert!(!any.allows(&addr("tcpout:127.0.0.1:5760")));
        assert_eq!(any.to_string(), "tcpout:[::1]:*");
        let names = LinkPattern::parse("tcpout:Vehicle.local:5760").unwrap();
        assert!(names.allows(&addr("tcpout:vehicle.LOCAL:5760")));
        let serial = LinkPattern::parse("serial:/dev/ttyACM0:*").unwrap();
        assert!(serial.allows(&addr("serial:/dev/ttyACM0:57600")));
        assert!(!serial.allows(&addr("serial:/dev/ttyACM1:57600")));
    }

    #[test]
    fn refuses_bad_entries_naming_the_fault() {
        for (text, why) in [
            ("127.0.0.1", "expected KIND:HOST:PORT"),
            ("udp:127.0.0.1:14550", "unknown link kind"),
            ("udpout:*:14550", "no wildcards"),
            ("udpout:127.0.0.1:14560-14550", "LO <= HI"),
            ("udpout:127.0.0.1:1-70000", "up to 65535"),
            ("udpout:127.0.0.1:0", "1 to 65535"),
            ("udpout:127.0.0.1:x-y", "port range"),
        ] {
            let e = LinkPattern::parse(text).expect_err(text);
            assert!(e.to_string().contains(why), "{text}: {e}");
        }
    }
}
