//! Names and ids a client gives: no control characters.
//!
//! They are stored and looked up as text as given. PostgreSQL's text
//! cannot hold NUL (`\u0000`) at all, so on it such a name failed the
//! insert (a 500, after the work was done) while SQLite took it; tabs,
//! line breaks and the other control characters only garble listings, logs
//! and download names. Both databases refuse them alike, when the request
//! is parsed, before any work.

use planner_core::geo::Issue;
use serde_json::Value;

/// Longest name a client may give a stored resource, in characters.
pub const NAME_MAX_CHARS: usize = 200;

/// The optional `name` member of a request body: absent or null is no
/// name; otherwise a string of at most [`NAME_MAX_CHARS`] characters
/// without control characters, or the fault at `/name`.
pub fn read_name(value: Option<&Value>) -> Result<Option<String>, Issue> {
    match value {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s)) => {
            if let Some(issue) = control_character_issue("/name", "the name", s) {
                Err(issue)
            } else if s.chars().count() <= NAME_MAX_CHARS {
                Ok(Some(s.clone()))
            } else {
                Err(Issue::new(
                    "/name",
                    &format!("the name is longer than {NAME_MAX_CHARS} characters"),
                ))
            }
        }
        Some(_) => Err(Issue::new("/name", "the name must be a string")),
    }
}

/// The first control character of `text` (Unicode category Cc: U+0000 to
/// U+001F, U+007F to U+009F), and its position counted in characters
/// from 1.
pub fn control_character(text: &str) -> Option<(usize, char)> {
    text.chars()
        .enumerate()
        .find(|(_, c)| c.is_control())
        .map(|(i, c)| (i + 1, c))
}

/// The fault of `text`, a name or id the request member at `pointer`
/// gives (`what` names it in the message), if it holds a control
/// character.
pub fn control_character_issue(pointer: &str, what: &str, text: &str) -> Option<Issue> {
    let (at, c) = control_character(text)?;
    Some(Issue::new(
        pointer,
        &format!(
            "{what} holds a control character (U+{:04X}) at character {at}: names and ids may not \
             hold control characters",
            u32::from(c)
        ),
    ))
}

/// Middleware (inside authentication, so an API caller without
/// credentials gets its 401 first): a path with a control character is a
/// 404 at once. No resource has such an id, and PostgreSQL cannot even
/// look one up (its text holds no NUL).
pub async fn refuse_control_characters(
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    if path_has_control_character(req.uri().path()) {
        return crate::error::ApiError::NotFound(format!(
            "there is no resource at {} {}: ids hold no control characters",
            req.method(),
            req.uri().path()
        ))
        .into_response();
    }
    next.run(req).await
}

/// Whether a URL path, percent-decoded, holds a control character: no
/// resource has such an id.
pub fn path_has_control_character(path: &str) -> bool {
    let bytes = path.as_bytes();
    let mut decoded = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| char::from(b).to_digit(16);
        if bytes[i] == b'%'
            && let (Some(hi), Some(lo)) = (
                bytes.get(i + 1).copied().and_then(hex),
                bytes.get(i + 2).copied().and_then(hex),
            )
        {
            decoded.push((hi * 16 + lo) as u8);
            i += 3;
        } else {
            decoded.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&decoded)
        .chars()
        .any(char::is_control)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_are_found() {
        assert_eq!(control_character("field 7"), None);
        assert_eq!(control_character("Überlingen – Süd ✈"), None);
        assert_eq!(control_character("a\u{0}b"), Some((2, '\u{0}')));
        assert_eq!(control_character("tab\there"), Some((4, '\t')));
        assert_eq!(control_character("\u{7f}"), Some((1, '\u{7f}')));
        assert_eq!(control_character("é\u{85}"), Some((2, '\u{85}')));
        let issue = control_character_issue("/name", "the name", "x\u{0}").unwrap();
        assert_eq!(issue.pointer, "/name");
        assert!(
            issue.message.contains("U+0000") && issue.message.contains("character 2"),
            "{}",
            issue.message
        );
        assert!(control_character_issue("/name", "the name", "fine").is_none());
    }

    #[test]
    fn paths_are_decoded() {
        assert!(!path_has_control_character("/api/v1/surveys/01a2-b3"));
        assert!(!path_has_control_character("/api/v1/surveys/a%20b%C3%A9"));
        assert!(path_has_control_character("/api/v1/surveys/a%00b"));
        assert!(path_has_control_character("/api/v1/surveys/%0a"));
        assert!(path_has_control_character("/api/v1/surveys/%7F"));
        assert!(path_has_control_character("/api/v1/surveys/%C2%85"));
        // Not an escape: left as it is.
        assert!(!path_has_control_character("/api/v1/surveys/%zz%0"));
    }
}
