//! Scene-file errors that name the file, line, column and key path, and the span ↔ key-path
//! mapping that produces them.
//!
//! Contract: every error a scene or board file can cause is a [`SceneError`] whose `Display` reads
//! ``file:line:column: `key.path[i].field`: message``. Syntax and schema errors come from the
//! `toml` crate's span-carrying errors (the key path is recovered from the span); semantic errors
//! are raised with a key path and located by walking the spanned document ([`toml::de::DeTable`]).
//! A key that is absent (a missing required field) is located at its nearest existing parent.

use ellipso_model::geometry::MeshError;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// An error in a scene or board file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// File path.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// TOML syntax, unknown keys, wrong types, missing required keys.
    #[error("{}:{line}:{column}: {}{message}", path.display(), key_prefix(key))]
    Parse {
        /// File path.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column (characters).
        column: usize,
        /// Dotted key path (empty at top level).
        key: String,
        /// The `toml` crate's message.
        message: String,
    },
    /// Well-formed TOML with a value that makes no physical or logical sense.
    #[error("{}:{line}:{column}: `{key}`: {message}", path.display())]
    Invalid {
        /// File path.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column (characters).
        column: usize,
        /// Dotted key path.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A mesh referenced by the scene failed to load.
    #[error("{}:{line}:{column}: `{key}`: mesh {}: {source}", path.display(), mesh.display())]
    Mesh {
        /// Scene file path.
        path: PathBuf,
        /// 1-based line of the `mesh` key.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Key path of the `mesh` entry.
        key: String,
        /// Resolved mesh path.
        mesh: PathBuf,
        /// What went wrong (boxed to keep the error small).
        source: Box<MeshError>,
    },
}

/// "`key`: " or nothing for an empty key.
fn key_prefix(key: &str) -> String {
    if key.is_empty() {
        String::new()
    } else {
        format!("`{key}`: ")
    }
}

impl SceneError {
    /// The offending key path (empty for I/O errors and top-level syntax errors).
    pub fn key(&self) -> &str {
        match self {
            Self::Io { .. } => "",
            Self::Parse { key, .. } | Self::Invalid { key, .. } | Self::Mesh { key, .. } => key,
        }
    }

    /// The 1-based line, if the error has one.
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Io { .. } => None,
            Self::Parse { line, .. } | Self::Invalid { line, .. } | Self::Mesh { line, .. } => {
                Some(*line)
            }
        }
    }

    /// The file the error is in.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. }
            | Self::Parse { path, .. }
            | Self::Invalid { path, .. }
            | Self::Mesh { path, .. } => path,
        }
    }
}

/// 1-based (line, column) of a byte offset.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..floor_char_boundary(text, offset)];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

fn floor_char_boundary(text: &str, mut i: usize) -> usize {
    while i > 0 && !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// One step of a key path.
#[derive(Clone, Debug, PartialEq)]
enum Seg {
    Key(String),
    Index(usize),
}

/// A key as it appears in a key path: bare if it is a TOML bare key (`A-Za-z0-9_-`), otherwise
/// quoted (`"Material.001"`), so dotted names stay one segment.
pub fn key_segment(name: &str) -> String {
    let bare = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare {
        name.to_string()
    } else {
        format!("\"{}\"", name.replace('\\', "\\\\").replace('"', "\\\""))
    }
}

/// Splits `a."b.c"[2].d` into segments (quoted keys may contain dots; `\"` escapes a quote).
fn segments(path: &str) -> Vec<Seg> {
    let mut out = Vec::new();
    let mut chars = path.chars().peekable();
    let mut key = String::new();
    let mut have_key = false;
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                while let Some(q) = chars.next() {
                    match q {
                        '\\' => key.extend(chars.next()),
                        '"' => break,
                        other => key.push(other),
                    }
                }
                have_key = true;
            }
            '.' => {
                if have_key || !key.is_empty() {
                    out.push(Seg::Key(std::mem::take(&mut key)));
                }
                have_key = false;
            }
            '[' => {
                if have_key || !key.is_empty() {
                    out.push(Seg::Key(std::mem::take(&mut key)));
                }
                have_key = false;
                let digits: String = chars.by_ref().take_while(|&d| d != ']').collect();
                if let Ok(i) = digits.parse() {
                    out.push(Seg::Index(i));
                }
            }
            other => key.push(other),
        }
    }
    if have_key || !key.is_empty() {
        out.push(Seg::Key(key));
    }
    out
}

/// A parsed TOML document that can map key paths to spans and back.
pub struct Located<'a> {
    /// Source text.
    pub text: &'a str,
    /// File path for messages.
    pub path: &'a Path,
    doc: Option<Spanned<DeTable<'a>>>,
}

impl<'a> Located<'a> {
    /// Parses `text` for location lookups (after a syntax error lookups give no key path).
    pub fn new(text: &'a str, path: &'a Path) -> Self {
        Self {
            text,
            path,
            // Strict parsing: after a syntax error a recovered tree can attribute the error to
            // the wrong key, so syntax errors carry the line and column only.
            doc: DeTable::parse(text).ok(),
        }
    }

    /// Span of the value at `key` (or of its nearest existing parent).
    pub fn span_of(&self, key: &str) -> Range<usize> {
        let Some(doc) = &self.doc else { return 0..0 };
        let mut span = 0..0;
        let mut table: Option<&DeTable<'_>> = Some(doc.get_ref());
        let mut array: Option<&[Spanned<DeValue<'_>>]> = None;
        for seg in segments(key) {
            let next = match (&seg, table, array) {
                (Seg::Key(k), Some(t), _) => t
                    .iter()
                    .find(|(name, _)| name.get_ref().as_ref() == k.as_str())
                    .map(|(_, v)| v),
                (Seg::Index(i), _, Some(a)) => a.get(*i),
                _ => None,
            };
            let Some(value) = next else { break };
            span = value.span();
            table = None;
            array = None;
            match value.get_ref() {
                DeValue::Table(t) => table = Some(t),
                DeValue::Array(a) => array = Some(a),
                _ => {}
            }
        }
        span
    }

    /// The innermost key path whose key or value span contains `offset`.
    pub fn key_at(&self, offset: usize) -> String {
        let Some(doc) = &self.doc else {
            return String::new();
        };
        let mut path = String::new();
        walk_table(doc.get_ref(), offset, &mut path);
        path
    }

    /// An [`SceneError::Invalid`] at `key`.
    pub fn invalid(&self, key: impl Into<String>, message: impl Into<String>) -> SceneError {
        let key = key.into();
        let (line, column) = line_column(self.text, self.span_of(&key).start);
        SceneError::Invalid {
            path: self.path.to_owned(),
            line,
            column,
            key,
            message: message.into(),
        }
    }

    /// A [`SceneError::Mesh`] at `key`.
    pub fn mesh(&self, key: impl Into<String>, mesh: PathBuf, source: MeshError) -> SceneError {
        let key = key.into();
        let (line, column) = line_column(self.text, self.span_of(&key).start);
        SceneError::Mesh {
            path: self.path.to_owned(),
            line,
            column,
            key,
            mesh,
            source: Box::new(source),
        }
    }

    /// Converts a `toml` deserialisation error, recovering the key path from its span.
    pub fn parse_error(&self, e: &toml::de::Error) -> SceneError {
        let offset = e.span().map_or(0, |s| s.start);
        let (line, column) = line_column(self.text, offset);
        SceneError::Parse {
            path: self.path.to_owned(),
            line,
            column,
            key: self.key_at(offset),
            message: e.message().trim().to_string(),
        }
    }
}

fn walk_table(t: &DeTable<'_>, offset: usize, path: &mut String) -> bool {
    for (k, v) in t.iter() {
        let in_key = k.span().contains(&offset);
        let in_value = v.span().contains(&offset);
        if in_key || in_value {
            if !path.is_empty() {
                path.push('.');
            }
            path.push_str(&key_segment(k.get_ref()));
            if in_value {
                walk_value(v.get_ref(), offset, path);
            }
            return true;
        }
    }
    // Tables written as `[a.b]` headers may not cover their body: search children anyway.
    for (k, v) in t.iter() {
        let len = path.len();
        if !path.is_empty() {
            path.push('.');
        }
        path.push_str(&key_segment(k.get_ref()));
        if walk_value(v.get_ref(), offset, path) {
            return true;
        }
        path.truncate(len);
    }
    false
}

fn walk_value(v: &DeValue<'_>, offset: usize, path: &mut String) -> bool {
    match v {
        DeValue::Table(t) => walk_table(t, offset, path),
        DeValue::Array(a) => {
            for (i, item) in a.iter().enumerate() {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                if item.span().contains(&offset) {
                    walk_value(item.get_ref(), offset, path);
                    return true;
                }
                if walk_value(item.get_ref(), offset, path) {
                    return true;
                }
                path.truncate(len);
            }
            false
        }
        _ => false,
    }
}

/// Checks a finite positive length.
pub fn positive(loc: &Located<'_>, key: &str, v: f64) -> Result<(), SceneError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(loc.invalid(key, format!("must be a positive, finite number, got {v}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = "seed = 1\n[rig.camera]\nfx_px = 100.0\n\n[[objects]]\nname = \"a\"\n\
                       [[objects]]\nname = \"b\"\npose = { translation_m = [1, 2, 3] }\n";

    #[test]
    fn key_paths_map_to_lines_and_back() {
        let loc = Located::new(DOC, Path::new("x.toml"));
        let (line, _) = line_column(DOC, loc.span_of("rig.camera.fx_px").start);
        assert_eq!(line, 3);
        let (line, _) = line_column(DOC, loc.span_of("objects[1].pose.translation_m").start);
        assert_eq!(line, 9);
        // Missing key: nearest parent.
        let (line, _) = line_column(DOC, loc.span_of("objects[1].radius_m").start);
        assert!(line >= 7, "{line}");
        let off = DOC.find("\"b\"").expect("present");
        assert_eq!(loc.key_at(off), "objects[1].name");
        let off = DOC.find("2, 3").expect("present");
        assert_eq!(loc.key_at(off), "objects[1].pose.translation_m[1]");
    }

    #[test]
    fn dotted_names_are_quoted_and_found() {
        let doc = "[materials.\"Material.001\"]\neta = 0.5\n";
        let loc = Located::new(doc, Path::new("x.toml"));
        let key = format!("materials.{}.eta", key_segment("Material.001"));
        assert_eq!(key, "materials.\"Material.001\".eta");
        assert_eq!(line_column(doc, loc.span_of(&key).start).0, 2);
        assert_eq!(loc.key_at(doc.find("0.5").expect("value")), key);
        assert_eq!(
            segments("a.\"b.c\"[2].d"),
            vec![
                Seg::Key("a".into()),
                Seg::Key("b.c".into()),
                Seg::Index(2),
                Seg::Key("d".into())
            ]
        );
    }

    #[test]
    fn line_column_counts_characters() {
        assert_eq!(line_column("ab\ncé d", 7), (2, 4));
        assert_eq!(line_column("", 5), (1, 1));
    }
}
