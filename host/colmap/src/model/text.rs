//! The text form of a COLMAP model (`cameras.txt`, `images.txt`, `points3D.txt`; the module
//! contract of `model` gives the lines): each reader returns its records sorted by id, or an
//! error naming the file and line.

use super::*;

/// The data lines of a file with their 1-based line numbers (comments and, unless
/// `keep_empty`, empty lines dropped).
fn lines(path: &Path, keep_empty: bool) -> Result<Vec<(usize, String)>, ModelError> {
    let text = std::fs::read_to_string(path).map_err(|error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    Ok(text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim().to_string()))
        .filter(|(_, l)| !l.starts_with('#') && (keep_empty || !l.is_empty()))
        .collect())
}

fn malformed(path: &Path, line: usize, what: impl Into<String>) -> ModelError {
    ModelError::Malformed {
        path: path.to_path_buf(),
        at: format!("line {line}"),
        what: what.into(),
    }
}

/// Parses field `k` of `f`.
fn field<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    f: &[&str],
    k: usize,
    name: &str,
) -> Result<T, ModelError> {
    let v = f
        .get(k)
        .ok_or_else(|| malformed(path, line, format!("no {name} (field {})", k + 1)))?;
    v.parse()
        .map_err(|_| malformed(path, line, format!("{name} `{v}` is not a number")))
}

pub(super) fn cameras(path: &Path) -> Result<Vec<ModelCamera>, ModelError> {
    lines(path, false)?
        .into_iter()
        .map(|(n, l)| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let model = f.get(1).copied().unwrap_or_default().to_string();
            let params = (4..f.len())
                .map(|k| field(path, n, &f, k, "parameter"))
                .collect::<Result<Vec<f64>, _>>()?;
            let expected = CAMERA_MODELS.iter().find(|m| m.0 == model).map(|m| m.1);
            if let Some(count) = expected.filter(|&c| c != params.len()) {
                return Err(malformed(
                    path,
                    n,
                    format!("{model} has {count} parameters, the line {}", params.len()),
                ));
            }
            if params.is_empty() {
                return Err(malformed(path, n, "a camera without parameters"));
            }
            Ok(ModelCamera {
                camera_id: field(path, n, &f, 0, "CAMERA_ID")?,
                model,
                width: field(path, n, &f, 2, "WIDTH")?,
                height: field(path, n, &f, 3, "HEIGHT")?,
                params,
            })
        })
        .collect()
}

pub(super) fn images(path: &Path) -> Result<Vec<ModelImage>, ModelError> {
    // as COLMAP reads it: an image line, then whatever line follows is its 2-D points
    let all = lines(path, true)?;
    let mut out = Vec::new();
    let mut rows = all.iter().peekable();
    while let Some((n, l)) = rows.next() {
        if l.is_empty() {
            continue;
        }
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() < 10 {
            return Err(malformed(
                path,
                *n,
                "an image line needs IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
            ));
        }
        let q: [f64; 4] = [
            field(path, *n, &f, 1, "QW")?,
            field(path, *n, &f, 2, "QX")?,
            field(path, *n, &f, 3, "QY")?,
            field(path, *n, &f, 4, "QZ")?,
        ];
        let t: [f64; 3] = [
            field(path, *n, &f, 5, "TX")?,
            field(path, *n, &f, 6, "TY")?,
            field(path, *n, &f, 7, "TZ")?,
        ];
        let camera_from_model = pose(q, t)
            .ok_or_else(|| malformed(path, *n, "the rotation is not a unit quaternion"))?;
        // names may hold spaces: everything after CAMERA_ID
        let name = f[9..].join(" ");
        let (mut points2d, mut triangulated) = (0, 0);
        if let Some((m, p)) = rows.next() {
            let g: Vec<&str> = p.split_whitespace().collect();
            if g.len() % 3 != 0 {
                return Err(malformed(
                    path,
                    *m,
                    "2-D points come in triples X Y POINT3D_ID",
                ));
            }
            for k in (0..g.len()).step_by(3) {
                let id: i64 = field(path, *m, &g, k + 2, "POINT3D_ID")?;
                points2d += 1;
                triangulated += usize::from(id >= 0);
            }
        }
        out.push(ModelImage {
            image_id: field(path, *n, &f, 0, "IMAGE_ID")?,
            camera_id: field(path, *n, &f, 8, "CAMERA_ID")?,
            name,
            camera_from_model,
            points2d,
            points2d_triangulated: triangulated,
        });
    }
    Ok(out)
}

pub(super) fn points(path: &Path) -> Result<Vec<ModelPoint>, ModelError> {
    lines(path, false)?
        .into_iter()
        .map(|(n, l)| {
            let f: Vec<&str> = l.split_whitespace().collect();
            if f.len() < 8 || (f.len() - 8) % 2 != 0 {
                return Err(malformed(
                    path,
                    n,
                    "a point line is POINT3D_ID X Y Z R G B ERROR then (IMAGE_ID POINT2D_IDX) pairs",
                ));
            }
            let position: Point3<f64> = Point3::new(
                field(path, n, &f, 1, "X")?,
                field(path, n, &f, 2, "Y")?,
                field(path, n, &f, 3, "Z")?,
            );
            if !position.coords.iter().all(|v| v.is_finite()) {
                return Err(malformed(path, n, "a non-finite position"));
            }
            Ok(ModelPoint {
                point3d_id: field(path, n, &f, 0, "POINT3D_ID")?,
                position,
                rgb: [
                    field(path, n, &f, 4, "R")?,
                    field(path, n, &f, 5, "G")?,
                    field(path, n, &f, 6, "B")?,
                ],
                error_px: field(path, n, &f, 7, "ERROR")?,
                track_length: (f.len() - 8) / 2,
            })
        })
        .collect()
}
