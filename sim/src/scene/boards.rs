//! Loading boards: standalone board files (`sim/boards/*.toml`, also read by the host's pose
//! tracker) and a scene's `[[boards]]` entries (file reference or inline table, plus a pose).
//!
//! Contract: errors in a board file point into that file (its path, line and key); errors in an
//! inline board point into the scene file under `boards[i].inline.…`. Tag ids must be unique
//! across all boards of a scene, otherwise a detection could not tell which board it saw.

use super::error::{Located, SceneError};
use super::spec::BoardRefSpec;
use ellipso_model::tags::{Board, BoardSpec, PlacedBoard};
use std::collections::HashMap;
use std::path::Path;

/// Reads and validates a standalone board file.
pub fn load_board_file(path: &Path) -> Result<Board, SceneError> {
    let text = ellipso_model::file_io::read_bounded_text(path, ellipso_model::file_io::caps::SCENE)
        .map_err(|source| SceneError::Io {
            path: path.to_owned(),
            source,
        })?;
    board_from_toml_str(&text, path)
}

/// Parses and validates board TOML; `path` is used in messages.
pub fn board_from_toml_str(text: &str, path: &Path) -> Result<Board, SceneError> {
    let loc = Located::new(text, path);
    let spec: BoardSpec = toml::from_str(text).map_err(|e| loc.parse_error(&e))?;
    Board::from_spec(&spec).map_err(|e| loc.invalid(e.key, e.message))
}

/// Builds a scene's boards; `base` is the scene file's folder.
pub fn build_boards(
    specs: &[BoardRefSpec],
    base: &Path,
    loc: &Located<'_>,
) -> Result<Vec<PlacedBoard>, SceneError> {
    let mut out = Vec::with_capacity(specs.len());
    // (family, id) → (board index, key of the tag's entry)
    let mut seen: HashMap<(&'static str, u32), (usize, String)> = HashMap::new();
    for (i, spec) in specs.iter().enumerate() {
        let key = format!("boards[{i}]");
        let (board, tag_key_prefix) = match (&spec.file, &spec.inline) {
            (Some(_), Some(_)) => {
                return Err(loc.invalid(
                    format!("{key}.inline"),
                    "give either file or inline, not both",
                ));
            }
            (None, None) => {
                return Err(loc.invalid(key, "needs `file = \"…\"` or a [boards.inline] table"));
            }
            (Some(file), None) => {
                let path = base.join(file);
                if !path.is_file() {
                    return Err(loc.invalid(
                        format!("{key}.file"),
                        super::not_a_file("board file", &path),
                    ));
                }
                (load_board_file(&path)?, None)
            }
            (None, Some(inline)) => {
                let board = Board::from_spec(inline)
                    .map_err(|e| loc.invalid(format!("{key}.inline.{}", e.key), e.message))?;
                (board, Some(format!("{key}.inline")))
            }
        };
        for (k, tag) in board.tags.iter().enumerate() {
            let at = match &tag_key_prefix {
                Some(p) => format!("{p}.{}", board.tag_key(k).unwrap_or("")),
                None => format!("{key}.file"),
            };
            if let Some((other, _)) = seen.insert((board.family.name(), tag.id), (i, at.clone())) {
                return Err(loc.invalid(
                    at,
                    format!(
                        "{} id {} is also on boards[{other}]: tag ids must be unique in a scene",
                        board.family.name(),
                        tag.id
                    ),
                ));
            }
        }
        let world_from_board = spec.pose.to_isometry(&format!("{key}.pose"), loc)?;
        out.push(PlacedBoard {
            board,
            world_from_board,
        });
    }
    Ok(out)
}
