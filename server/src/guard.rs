//! Answers the browser must be able to trust: only for the host names
//! this service is configured for (against DNS rebinding), and with
//! security headers on every response (no MIME sniffing, a Content
//! Security Policy, no referrer leaks, no framing).

use axum::extract::Request;
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::error::ApiError;

/// The page's policy: everything from this origin, map tiles from any
/// https server (the "Online base map"), images the page draws itself.
/// OpenLayers sets element styles from script, which CSP allows.
const PAGE_POLICY: &str = "default-src 'self'; img-src 'self' data: blob: https:; \
    style-src 'self'; script-src 'self'; connect-src 'self'; worker-src 'self' blob:; \
    object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'none'";

/// Swagger UI (`/api/docs`) starts itself with an inline script and styles.
const DOCS_POLICY: &str = "default-src 'self'; img-src 'self' data:; \
    style-src 'self' 'unsafe-inline'; script-src 'self' 'unsafe-inline'; connect-src 'self'; \
    object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'none'";

/// The host names requests may name in `Host`.
#[derive(Clone, Debug)]
pub struct AllowedHosts {
    /// Lower-case names without port; `None`: any host (`--allowed-host '*'`).
    names: Option<Vec<String>>,
}

impl AllowedHosts {
    /// The loopback names, the address the service listens on when it is
    /// a specific one, and the configured names (`*`: any).
    pub fn new(listen_host: &str, configured: &[String]) -> AllowedHosts {
        if configured.iter().any(|h| h.trim() == "*") {
            return AllowedHosts { names: None };
        }
        let mut names: Vec<String> = ["localhost", "127.0.0.1", "::1"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let listen = listen_host.trim_matches(['[', ']']).to_ascii_lowercase();
        if !listen.is_empty() && listen != "0.0.0.0" && listen != "::" {
            names.push(listen);
        }
        names.extend(
            configured
                .iter()
                .map(|h| h.trim().trim_matches(['[', ']']).to_ascii_lowercase())
                .filter(|h| !h.is_empty()),
        );
        AllowedHosts { names: Some(names) }
    }

    /// Whether a `Host` header value (name, optional port) is allowed.
    pub fn allows(&self, host: &str) -> bool {
        let Some(names) = &self.names else {
            return true;
        };
        let name = host_name(host).to_ascii_lowercase();
        names.contains(&name)
            || (name.ends_with(".localhost") && names.iter().any(|n| n == "localhost"))
    }
}

/// The name part of a `Host` value: `[::1]:8080` → `::1`, `a.b:80` → `a.b`.
fn host_name(host: &str) -> &str {
    if let Some(rest) = host.strip_prefix('[') {
        return rest.split(']').next().unwrap_or_default();
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
        _ => host,
    }
}

/// Middleware: refuse a request whose `Host` is not allowed (400
/// problem+json naming the flag), so a page on another site that has its
/// name resolved to this machine cannot reach the service; `/healthz`
/// stays open to probes that name the machine by address.
pub async fn check_host(allowed: AllowedHosts, req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(header::HOST)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string)
        .or_else(|| req.uri().authority().map(|a| a.to_string()));
    let ok = match &host {
        Some(h) => allowed.allows(h),
        None => true, // HTTP/1.0 without Host: no name to rebind
    };
    if ok || req.uri().path() == "/healthz" {
        return next.run(req).await;
    }
    let host = host.unwrap_or_default();
    ApiError::BadRequest(format!(
        "this service does not answer to the host name {:?}: start it with --allowed-host NAME \
         (or TERRAPLAN_ALLOWED_HOSTS) to allow it",
        host_name(&host)
    ))
    .into_response()
}

/// Middleware: the security headers of every response.
pub async fn security_headers(req: Request, next: Next) -> Response {
    let docs = req.uri().path().starts_with("/api/docs");
    let mut res = next.run(req).await;
    let h = res.headers_mut();
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(if docs { DOCS_POLICY } else { PAGE_POLICY }),
    );
    res
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_names_are_allowed_by_default_and_others_are_not() {
        let a = AllowedHosts::new("127.0.0.1", &[]);
        for ok in [
            "localhost",
            "localhost:8080",
            "127.0.0.1:1",
            "[::1]:80",
            "LOCALHOST",
            "app.localhost:3",
        ] {
            assert!(a.allows(ok), "{ok}");
        }
        for bad in [
            "evil.example",
            "evil.example:8080",
            "127.0.0.2",
            "localhost.evil.example",
            "",
        ] {
            assert!(!a.allows(bad), "{bad}");
        }
    }

    #[test]
    fn configured_and_listen_names_are_allowed_star_allows_all() {
        let a = AllowedHosts::new("10.1.2.3", &["Survey.Example.org".to_string()]);
        assert!(a.allows("10.1.2.3:8080"));
        assert!(a.allows("survey.example.org"));
        assert!(!a.allows("example.org"));
        let any_listen = AllowedHosts::new("0.0.0.0", &[]);
        assert!(!any_listen.allows("0.0.0.0"));
        assert!(AllowedHosts::new("0.0.0.0", &["*".to_string()]).allows("anything.example"));
    }
}
