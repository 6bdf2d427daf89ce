//! Bearer secrets: API tokens (`tp_…`) and session keys (`ts_…`). Each is
//! `{prefix}_{id}_{secret}`: the id (16 hex characters) names the stored
//! row, the secret (32 random bytes, base64url) is kept only as its SHA-256
//! and compared in constant time. 256 random bits need no slow hash.

use base64::Engine;
use base64::engine::general_purpose::URL_SAFE_NO_PAD;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// The prefix of API tokens.
pub const TOKEN_PREFIX: &str = "tp";
/// The prefix of session keys (the session cookie's value).
pub const SESSION_PREFIX: &str = "ts";

const ID_CHARS: usize = 16;
const SECRET_CHARS: usize = 43;

/// A new secret: what the holder is given once, and what is stored.
pub struct NewSecret {
    /// `{prefix}_{id}_{secret}`, shown once.
    pub full: String,
    pub id: String,
    /// Hex SHA-256 of the secret part.
    pub hash: String,
}

/// `n` random bytes from the operating system.
pub fn random_bytes<const N: usize>() -> [u8; N] {
    let mut bytes = [0u8; N];
    getrandom::fill(&mut bytes).expect("the operating system's random number generator");
    bytes
}

/// A random string of 43 base64url characters (256 bits), for CSRF tokens
/// and generated passwords' material.
pub fn random_text() -> String {
    URL_SAFE_NO_PAD.encode(random_bytes::<32>())
}

/// A new secret with `prefix` (`TOKEN_PREFIX` or `SESSION_PREFIX`).
pub fn new_secret(prefix: &str) -> NewSecret {
    let id = hex::encode(random_bytes::<8>());
    let secret = random_text();
    let hash = hash(&secret);
    NewSecret {
        full: format!("{prefix}_{id}_{secret}"),
        id,
        hash,
    }
}

/// The id and secret of `text` when it has the shape of a `prefix` secret.
pub fn parse<'a>(prefix: &str, text: &'a str) -> Option<(&'a str, &'a str)> {
    let rest = text.strip_prefix(prefix)?.strip_prefix('_')?;
    if rest.len() != ID_CHARS + 1 + SECRET_CHARS || !rest.is_ascii() {
        return None;
    }
    let (id, secret) = rest.split_at(ID_CHARS);
    let secret = secret.strip_prefix('_')?;
    let id_ok = id
        .bytes()
        .all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase());
    let secret_ok = secret
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    (id_ok && secret_ok).then_some((id, secret))
}

/// Hex SHA-256 of a secret, as stored.
pub fn hash(secret: &str) -> String {
    hex::encode(Sha256::digest(secret.as_bytes()))
}

/// Whether `secret` is the one stored as `stored_hash`, in constant time.
pub fn matches(secret: &str, stored_hash: &str) -> bool {
    hash(secret).as_bytes().ct_eq(stored_hash.as_bytes()).into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_secret_parses_back_and_matches_only_its_hash() {
        let s = new_secret(TOKEN_PREFIX);
        assert!(s.full.starts_with("tp_"));
        let (id, secret) = parse(TOKEN_PREFIX, &s.full).expect("parses");
        assert_eq!(id, s.id);
        assert!(matches(secret, &s.hash));
        assert!(
            !s.full.contains(&s.hash),
            "the stored hash is not the secret"
        );
        let other = new_secret(TOKEN_PREFIX);
        assert_ne!(other.full, s.full);
        assert!(!matches(secret, &other.hash));
    }

    #[test]
    fn malformed_secrets_do_not_parse() {
        let s = new_secret(SESSION_PREFIX);
        assert!(parse(TOKEN_PREFIX, &s.full).is_none(), "wrong prefix");
        assert!(parse(SESSION_PREFIX, &s.full[..s.full.len() - 1]).is_none());
        assert!(parse(SESSION_PREFIX, &format!("{}x", s.full)).is_none());
        assert!(parse(SESSION_PREFIX, &s.full.to_uppercase()).is_none());
        assert!(parse(TOKEN_PREFIX, "tp_").is_none());
        assert!(parse(TOKEN_PREFIX, "").is_none());
        let non_ascii = format!("tp_{}_{}é", "0".repeat(16), "a".repeat(41));
        assert!(parse(TOKEN_PREFIX, &non_ascii).is_none());
    }
}
