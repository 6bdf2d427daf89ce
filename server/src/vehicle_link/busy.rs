//! The service's vehicle links: the allow-list of `serve --vehicle-links`
//! and the addresses an upload is using now (one upload per address at a
//! time: two missions interleaved on one vehicle would corrupt both).

use std::collections::HashSet;
use std::sync::{Arc, Mutex};

use super::address::VehicleAddress;
use super::allow::LinkPattern;

/// What the service may reach, and what it is reaching.
#[derive(Debug, Default)]
pub struct VehicleLinks {
    allowed: Vec<LinkPattern>,
    busy: Arc<Mutex<HashSet<String>>>,
}

/// An address held by one upload; let go when dropped.
#[derive(Debug)]
pub struct Claim {
    key: String,
    busy: Arc<Mutex<HashSet<String>>>,
}

impl Drop for Claim {
    fn drop(&mut self) {
        if let Ok(mut busy) = self.busy.lock() {
            busy.remove(&self.key);
        }
    }
}

impl VehicleLinks {
    pub fn new(allowed: Vec<LinkPattern>) -> VehicleLinks {
        VehicleLinks {
            allowed,
            busy: Arc::default(),
        }
    }

    /// Uploads are switched on (`--vehicle-links` named at least one).
    pub fn enabled(&self) -> bool {
        !self.allowed.is_empty()
    }

    /// The allow-list, as configured.
    pub fn allowed(&self) -> &[LinkPattern] {
        &self.allowed
    }

    /// Whether an entry allows `address`.
    pub fn allows(&self, address: &VehicleAddress) -> bool {
        self.allowed.iter().any(|p| p.allows(address))
    }

    /// Hold `address` for one upload; `None` while another holds it.
    /// Addresses are compared in canonical form, host names without case.
    pub fn claim(&self, address: &VehicleAddress) -> Option<Claim> {
        let key = address.to_string().to_ascii_lowercase();
        let mut busy = self.busy.lock().unwrap_or_else(|e| e.into_inner());
        busy.insert(key.clone()).then(|| Claim {
            key,
            busy: self.busy.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_claim_per_address_until_it_is_dropped() {
        let links = VehicleLinks::new(vec![LinkPattern::parse("udpout:127.0.0.1:*").unwrap()]);
        assert!(links.enabled());
        let a = VehicleAddress::parse("udpout:127.0.0.1:14550").unwrap();
        let b = VehicleAddress::parse("udpout:127.0.0.1:14551").unwrap();
        assert!(links.allows(&a));
        assert!(!links.allows(&VehicleAddress::parse("udpout:10.0.0.1:14550").unwrap()));
        let held = links.claim(&a).expect("free");
        assert!(links.claim(&a).is_none(), "busy while held");
        assert!(links.claim(&b).is_some(), "another address is free");
        drop(held);
        assert!(links.claim(&a).is_some(), "free again");
        assert!(!VehicleLinks::default().enabled());
    }
}
