//! The page and its assets (HTML, the ES modules, CSS), built into the
//! binary, and the headers they are served with: nothing is loaded from
//! anywhere else.

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

/// The page.
pub const INDEX_HTML: &str = include_str!("index.html");
/// Its style sheet.
pub const VIEWER_CSS: &str = include_str!("viewer.css");

/// The script's ES modules (`/viewer/js/{name}`), the entry point first;
/// they import one another by relative paths (`./math.js`).
pub const MODULES: [(&str, &str); 20] = [
    ("main.js", include_str!("js/main.js")),
    ("dom.js", include_str!("js/dom.js")),
    ("state.js", include_str!("js/state.js")),
    ("context.js", include_str!("js/context.js")),
    ("api.js", include_str!("js/api.js")),
    ("math.js", include_str!("js/math.js")),
    ("camera.js", include_str!("js/camera.js")),
    ("shapes.js", include_str!("js/shapes.js")),
    ("gl.js", include_str!("js/gl.js")),
    ("scene.js", include_str!("js/scene.js")),
    ("render.js", include_str!("js/render.js")),
    ("pick.js", include_str!("js/pick.js")),
    ("frames.js", include_str!("js/frames.js")),
    ("panel.js", include_str!("js/panel.js")),
    ("loading.js", include_str!("js/loading.js")),
    ("knots.js", include_str!("js/knots.js")),
    ("live.js", include_str!("js/live.js")),
    ("input.js", include_str!("js/input.js")),
    ("highlight.js", include_str!("js/highlight.js")),
    ("adjust.js", include_str!("js/adjust.js")),
];

/// Everything the page may load: itself. No remote scripts, styles, fonts or images.
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'";

/// The source of module `name`, if the viewer has one of that name.
pub fn module_source(name: &str) -> Option<&'static str> {
    MODULES.iter().find(|(n, _)| *n == name).map(|(_, source)| *source)
}

/// The modules' names, for an error naming them.
pub fn module_names() -> String {
    MODULES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

/// An asset answered with its type and the page's security headers.
pub fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
            (header::CONTENT_SECURITY_POLICY, HeaderValue::from_static(CSP)),
            (header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff")),
        ],
        body,
    )
        .into_response()
}
