//! The page's files, embedded in the binary: no CDN, no network, works offline.
//!
//! Contract: [`get`] returns a file's bytes and content type by name (`None` for any other
//! name, so nothing outside this list is ever served); [`page`] fills an HTML template's
//! `{{MODE}}` and `{{TOKEN}}` (the token is only ever written into pages that were themselves
//! requested with it). All scripts are hand-written (WebGL2, Canvas 2D, EventSource); there is
//! no third-party code.

const FILES: [(&str, &str, &str); 9] = [
    (
        "index.html",
        include_str!("assets/index.html"),
        "text/html; charset=utf-8",
    ),
    (
        "check.html",
        include_str!("assets/check.html"),
        "text/html; charset=utf-8",
    ),
    (
        "style.css",
        include_str!("assets/style.css"),
        "text/css; charset=utf-8",
    ),
    (
        "common.js",
        include_str!("assets/common.js"),
        "text/javascript; charset=utf-8",
    ),
    (
        "material.js",
        include_str!("assets/material.js"),
        "text/javascript; charset=utf-8",
    ),
    (
        "live.js",
        include_str!("assets/live.js"),
        "text/javascript; charset=utf-8",
    ),
    (
        "check.js",
        include_str!("assets/check.js"),
        "text/javascript; charset=utf-8",
    ),
    (
        "pbrdf.glsl",
        include_str!("assets/pbrdf.glsl"),
        "text/plain; charset=utf-8",
    ),
    (
        "mesh.js",
        include_str!("assets/mesh.js"),
        "text/javascript; charset=utf-8",
    ),
];

/// A file by name: `(bytes, content type)`.
pub fn get(name: &str) -> Option<(&'static [u8], &'static str)> {
    FILES
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, body, ty)| (body.as_bytes(), *ty))
}

/// An HTML template with its mode and token filled in.
pub fn page(name: &str, mode: &str, token: &str) -> String {
    let template = FILES
        .iter()
        .find(|(n, _, _)| *n == name)
        .map_or("", |(_, body, _)| *body);
    template
        .replace("{{MODE}}", mode)
        .replace("{{TOKEN}}", token)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_listed_files_are_served_and_nothing_is_remote() {
        assert!(get("index.html").is_some());
        assert!(get("../Cargo.toml").is_none());
        assert!(get("").is_none());
        for (name, body, _) in FILES {
            for remote in ["http://", "https://", "//cdn", "import("] {
                assert!(!body.contains(remote), "{name} refers to {remote}");
            }
        }
        let p = page("index.html", "live", "abc123");
        assert!(p.contains("abc123") && !p.contains("{{"));
    }
}
