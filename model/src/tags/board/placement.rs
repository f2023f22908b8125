//! A board spec checked and laid out on its sheet: the print's numbers, the grid's and the
//! explicit tags' placements (ids in the family, none twice, no two overlapping with their
//! quiet zones) and the sheet's size, given or the tags' extent plus the margin. Contract: the
//! first problem found, in the spec's order, is the error, naming its key; a layout returned
//! is one [`super::Board::from_spec`] can build without further checks.

use std::collections::HashMap;

use nalgebra::Vector2;

use super::{BoardError, BoardSpec, GridSpec};

fn bad(key: impl Into<String>, message: impl Into<String>) -> BoardError {
    BoardError {
        key: key.into(),
        message: message.into(),
    }
}

/// One tag the spec places, before the board frame is known.
pub(super) struct PlacedTag {
    /// Key path of the spec entry that placed it (for error messages).
    pub key: String,
    /// Tag id.
    pub id: u32,
    /// Centre in sheet coordinates, metres.
    pub centre_sheet_m: Vector2<f64>,
    /// In-plane rotation (clockwise seen from the front), radians.
    pub rotation_rad: f64,
}

/// A checked spec's tags on its sheet.
pub(super) struct Layout {
    /// Tags in spec order (grid first, then explicit placements).
    pub placed: Vec<PlacedTag>,
    /// Sheet `[width, height]`, metres.
    pub sheet_size_m: [f64; 2],
    /// Half the side of a tag with its quiet zone, metres.
    pub outer_half: f64,
}

/// Checks `spec` and lays its tags out on the sheet; errors name the offending key.
pub(super) fn lay_out(spec: &BoardSpec) -> Result<Layout, BoardError> {
    check_print(spec)?;
    let table = spec.family.code_table();
    let s = spec.tag_size_m;
    let cell = s / table.width_at_border as f64;
    let quiet = table.quiet_zone_cells() as f64 * cell;
    let mut placed = match &spec.grid {
        Some(g) => grid_tags(spec, g, quiet)?,
        None => Vec::new(),
    };
    for (k, t) in spec.tags.iter().enumerate() {
        if !(t.centre_m.iter().all(|v| v.is_finite()) && t.rotation_deg.is_finite()) {
            return Err(bad(
                format!("tags[{k}]"),
                "centre_m and rotation_deg must be finite",
            ));
        }
        placed.push(PlacedTag {
            key: format!("tags[{k}].id"),
            id: t.id,
            centre_sheet_m: Vector2::from(t.centre_m),
            rotation_rad: t.rotation_deg.to_radians(),
        });
    }
    if placed.is_empty() {
        return Err(bad("grid", "a board needs tags: give `grid` or `[[tags]]`"));
    }
    check_ids(spec, &placed)?;
    check_overlaps(&placed, s, quiet)?;
    let outer_half = 0.5 * s + quiet;
    let sheet_size_m = sheet_size(spec, &placed, outer_half)?;
    Ok(Layout {
        placed,
        sheet_size_m,
        outer_half,
    })
}

/// The print's numbers: tag size, margin and the two albedos.
fn check_print(spec: &BoardSpec) -> Result<(), BoardError> {
    let s = spec.tag_size_m;
    if !(s.is_finite() && s > 0.0) {
        return Err(bad(
            "tag_size_m",
            format!("must be a positive length, got {s}"),
        ));
    }
    if !(spec.margin_m.is_finite() && spec.margin_m >= 0.0) {
        return Err(bad("margin_m", "must be a non-negative length"));
    }
    for (key, v) in [
        ("white_albedo", spec.white_albedo),
        ("black_albedo", spec.black_albedo),
    ] {
        if !(0.0..=1.0).contains(&v) {
            return Err(bad(key, format!("albedo must be in [0, 1], got {v}")));
        }
    }
    if spec.black_albedo >= spec.white_albedo {
        return Err(bad("black_albedo", "must be darker than white_albedo"));
    }
    Ok(())
}

/// The grid's tags, row by row, unrotated (`quiet`: the quiet zone's width, metres).
fn grid_tags(spec: &BoardSpec, g: &GridSpec, quiet: f64) -> Result<Vec<PlacedTag>, BoardError> {
    let table = spec.family.code_table();
    let s = spec.tag_size_m;
    if g.cols == 0 || g.rows == 0 {
        let key = if g.cols == 0 {
            "grid.cols"
        } else {
            "grid.rows"
        };
        return Err(bad(key, "a grid needs at least one column and one row"));
    }
    if !(g.spacing_m.is_finite() && g.spacing_m >= s + quiet) {
        return Err(bad(
            "grid.spacing_m",
            format!(
                "{} m leaves less than the {quiet:.4} m quiet zone between {s} m tags \
                 (need ≥ {:.4} m)",
                g.spacing_m,
                s + quiet
            ),
        ));
    }
    let n = g.cols as usize * g.rows as usize;
    if n > table.len() {
        return Err(bad(
            "grid.cols",
            format!(
                "{}×{} tags exceed the {} codes of {}",
                g.cols,
                g.rows,
                table.len(),
                spec.family.name()
            ),
        ));
    }
    let ids: Vec<(String, u32)> = match &g.ids {
        Some(ids) if ids.len() != n => {
            return Err(bad(
                "grid.ids",
                format!(
                    "{} ids for a {}×{} grid (need {n})",
                    ids.len(),
                    g.cols,
                    g.rows
                ),
            ));
        }
        Some(ids) => ids
            .iter()
            .enumerate()
            .map(|(k, &i)| (format!("grid.ids[{k}]"), i))
            .collect(),
        None => (0..n as u32)
            .map(|k| ("grid.first_id".to_string(), g.first_id.saturating_add(k)))
            .collect(),
    };
    let first = match g.first_centre_m {
        Some(c) => Vector2::from(c),
        None => Vector2::repeat(spec.margin_m + quiet + 0.5 * s),
    };
    if !first.iter().all(|v| v.is_finite()) {
        return Err(bad("grid.first_centre_m", "must be finite"));
    }
    Ok(ids
        .into_iter()
        .enumerate()
        .map(|(k, (key, id))| {
            let (c, r) = ((k as u32 % g.cols) as f64, (k as u32 / g.cols) as f64);
            PlacedTag {
                key,
                id,
                centre_sheet_m: first + Vector2::new(c, r) * g.spacing_m,
                rotation_rad: 0.0,
            }
        })
        .collect())
}

/// Every id is in the family and placed once.
fn check_ids(spec: &BoardSpec, placed: &[PlacedTag]) -> Result<(), BoardError> {
    let table = spec.family.code_table();
    let mut seen: HashMap<u32, String> = HashMap::new();
    for PlacedTag { key, id, .. } in placed {
        if *id as usize >= table.len() {
            return Err(bad(
                key.clone(),
                format!(
                    "id {id} is not in {} (ids 0..{})",
                    spec.family.name(),
                    table.len() - 1
                ),
            ));
        }
        if let Some(prev) = seen.insert(*id, key.clone()) {
            return Err(bad(
                key.clone(),
                format!("id {id} appears twice (also at `{prev}`)"),
            ));
        }
    }
    Ok(())
}

/// Tags (with one quiet zone between them) must not overlap: separating-axis test on the
/// squares of side s + quiet.
fn check_overlaps(placed: &[PlacedTag], s: f64, quiet: f64) -> Result<(), BoardError> {
    let half = 0.5 * (s + quiet) - 1e-12;
    for i in 0..placed.len() {
        for j in 0..i {
            let (a, b) = (&placed[i], &placed[j]);
            if squares_overlap(
                a.centre_sheet_m,
                a.rotation_rad,
                b.centre_sheet_m,
                b.rotation_rad,
                half,
            ) {
                return Err(bad(
                    a.key.clone(),
                    format!(
                        "tag {} overlaps tag {} (or leaves no {quiet:.4} m quiet zone)",
                        a.id, b.id
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The sheet: given, or the tags' extent including quiet zone plus margin; every tag with its
/// quiet zone must lie on it.
fn sheet_size(
    spec: &BoardSpec,
    placed: &[PlacedTag],
    outer_half: f64,
) -> Result<[f64; 2], BoardError> {
    let extent = |p: &PlacedTag| {
        let (c, rot) = (p.centre_sheet_m, p.rotation_rad);
        let r = outer_half * (rot.cos().abs() + rot.sin().abs());
        (c - Vector2::repeat(r), c + Vector2::repeat(r))
    };
    let sheet_size_m = match spec.sheet_size_m {
        Some([w, h]) => {
            if !(w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
                return Err(bad(
                    "sheet_size_m",
                    format!("must be positive, got [{w}, {h}]"),
                ));
            }
            [w, h]
        }
        None => {
            let max = placed
                .iter()
                .map(extent)
                .fold(Vector2::zeros(), |m, (_, hi)| m.sup(&hi));
            [max.x + spec.margin_m, max.y + spec.margin_m]
        }
    };
    for p in placed {
        let (lo, hi) = extent(p);
        let tol = 1e-9;
        if lo.x < -tol
            || lo.y < -tol
            || hi.x > sheet_size_m[0] + tol
            || hi.y > sheet_size_m[1] + tol
        {
            return Err(bad(
                p.key.clone(),
                format!(
                    "tag {} with its quiet zone reaches outside the {} × {} m sheet",
                    p.id, sheet_size_m[0], sheet_size_m[1]
                ),
            ));
        }
    }
    Ok(sheet_size_m)
}

/// Separating-axis test for two squares of half-side `half` (centres, rotations in radians).
fn squares_overlap(ca: Vector2<f64>, ra: f64, cb: Vector2<f64>, rb: f64, half: f64) -> bool {
    let axes = |r: f64| {
        [
            Vector2::new(r.cos(), r.sin()),
            Vector2::new(-r.sin(), r.cos()),
        ]
    };
    let corners = |c: Vector2<f64>, r: f64| {
        let [u, v] = axes(r);
        [
            c + (u + v) * half,
            c + (u - v) * half,
            c - (u + v) * half,
            c - (u - v) * half,
        ]
    };
    let (pa, pb) = (corners(ca, ra), corners(cb, rb));
    for axis in axes(ra).into_iter().chain(axes(rb)) {
        let proj = |pts: &[Vector2<f64>; 4]| {
            pts.iter()
                .map(|p| p.dot(&axis))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let ((a0, a1), (b0, b1)) = (proj(&pa), proj(&pb));
        if a1 <= b0 || b1 <= a0 {
            return false;
        }
    }
    true
}
