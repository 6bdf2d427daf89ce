//! The browser front end (web-ui/, built by Vite) served at `/`: its files
//! from `--web-dir`, and `index.html` for any other path outside `/api`,
//! so the page's own links can be reloaded. Hashed assets are cached for
//! good; `index.html` is always revalidated.

use std::path::{Path, PathBuf};

use axum::body::Body;
use axum::extract::Request;
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use tower::ServiceExt;
use tower_http::services::{ServeDir, ServeFile};

/// Where the built page is, if it is built.
#[derive(Clone, Debug)]
pub struct WebUi {
    dir: Option<PathBuf>,
    wanted: PathBuf,
}

impl WebUi {
    /// The page in `dir` when `dir/index.html` exists.
    pub fn new(dir: &Path) -> WebUi {
        WebUi {
            dir: dir.join("index.html").is_file().then(|| dir.to_path_buf()),
            wanted: dir.to_path_buf(),
        }
    }

    pub fn is_built(&self) -> bool {
        self.dir.is_some()
    }

    /// Answer a GET or HEAD outside `/api` with the page's files.
    pub async fn serve(&self, req: Request) -> Response {
        if req.method() != Method::GET && req.method() != Method::HEAD {
            return StatusCode::METHOD_NOT_ALLOWED.into_response();
        }
        let Some(dir) = &self.dir else {
            return (
                StatusCode::SERVICE_UNAVAILABLE,
                Html(format!(
                    "<!doctype html><title>terraplan</title><h1>terraplan</h1>\
                     <p>The web page is not built ({} has no index.html). \
                     <code>bash scripts/run.sh</code> builds it; so does \
                     <code>npm --prefix web-ui ci &amp;&amp; npm --prefix web-ui run build</code>.</p>\
                     <p>The API works: <a href=\"/api/docs/\">its documentation</a>.</p>",
                    self.wanted.display()
                )),
            )
                .into_response();
        };
        let assets = req.uri().path().starts_with("/assets/");
        let index = ServeFile::new(dir.join("index.html"));
        let mut res = match ServeDir::new(dir).fallback(index).oneshot(req).await {
            Ok(res) => res.map(Body::new),
            Err(never) => match never {},
        };
        let cache = if assets && res.status().is_success() {
            // Vite names them by content hash.
            "public, max-age=31536000, immutable"
        } else {
            "no-cache"
        };
        res.headers_mut()
            .insert(header::CACHE_CONTROL, HeaderValue::from_static(cache));
        res
    }
}
