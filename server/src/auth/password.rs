//! Passwords: argon2id hashes (PHC strings) with the crate's default cost,
//! and the length rules a new password must meet.

use argon2::Argon2;
use argon2::password_hash::{PasswordHash, PasswordHasher, PasswordVerifier, SaltString};

/// Shortest password accepted.
pub const MIN_CHARS: usize = 8;
/// Longest password accepted, in bytes (hashing cost grows with it).
pub const MAX_BYTES: usize = 1024;

/// Why a new password is refused; `None` when it is acceptable.
pub fn fault(password: &str) -> Option<String> {
    if password.chars().count() < MIN_CHARS {
        Some(format!("a password needs at least {MIN_CHARS} characters"))
    } else if password.len() > MAX_BYTES {
        Some(format!("a password may have at most {MAX_BYTES} bytes"))
    } else {
        None
    }
}

/// The argon2id PHC string of `password`, with a random salt.
pub fn hash(password: &str) -> String {
    let salt = SaltString::encode_b64(&super::secret::random_bytes::<16>())
        .expect("16 bytes make a valid salt");
    Argon2::default()
        .hash_password(password.as_bytes(), &salt)
        .expect("argon2id with default parameters hashes any password")
        .to_string()
}

/// Whether `password` is the one hashed as `phc`.
pub fn verify(password: &str, phc: &str) -> bool {
    if password.len() > MAX_BYTES {
        return false;
    }
    PasswordHash::new(phc)
        .map(|parsed| {
            Argon2::default()
                .verify_password(password.as_bytes(), &parsed)
                .is_ok()
        })
        .unwrap_or(false)
}

/// A password hash to verify against when the user does not exist, so a
/// wrong name costs the same time as a wrong password.
pub fn decoy_hash() -> &'static str {
    static DECOY: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    DECOY.get_or_init(|| hash(&super::secret::random_text()))
}

/// A generated password: 20 characters from an unambiguous alphabet.
pub fn generate() -> String {
    const ALPHABET: &[u8] = b"abcdefghijkmnopqrstuvwxyzABCDEFGHJKLMNPQRSTUVWXYZ23456789";
    super::secret::random_bytes::<20>()
        .iter()
        .map(|b| ALPHABET[*b as usize % ALPHABET.len()] as char)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn argon2id_hash_verifies_only_its_password() {
        let h = hash("correct horse battery");
        assert!(h.starts_with("$argon2id$"), "{h}");
        assert!(!h.contains("correct horse"));
        assert!(verify("correct horse battery", &h));
        assert!(!verify("correct horse batterY", &h));
        assert!(!verify("correct horse battery", "not a phc string"));
        assert_ne!(hash("correct horse battery"), h, "salted");
    }

    #[test]
    fn length_rules_and_generated_passwords() {
        assert!(fault("short").is_some());
        assert!(fault(&"x".repeat(MAX_BYTES + 1)).is_some());
        assert!(fault("eight ch").is_none());
        let p = generate();
        assert_eq!(p.len(), 20);
        assert!(fault(&p).is_none());
        assert_ne!(generate(), p);
    }
}
