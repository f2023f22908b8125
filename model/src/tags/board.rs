//! AprilTag boards: the TOML description ([`BoardSpec`]), its validation, and the built [`Board`]
//! that answers albedo lookups, tag corner coordinates and ray–board intersections.
//!
//! Frames (all metres):
//! - *Sheet* frame: the printed sheet laid out like a page: origin at its top-left corner, x right,
//!   y down, z into the sheet (away from the viewer). Layout positions are given in this frame.
//! - *Board* frame: the frame poses refer to. Origin at the sheet's top-left corner or centre
//!   (`origin`); axes either the sheet's (`x_right_y_down`, z into the board — AprilTag's and
//!   OpenCV's convention) or `x_right_y_up` (z out of the board towards the viewer). The sheet
//!   lies in the board's `z = 0` plane.
//! - *Tag* frame: AprilTag's: centre of the tag, x right, y down, z into the tag, as seen on the
//!   upright printed tag. `board_from_tag` is what pose estimation recovers per tag.
//!
//! Corner order: [`BoardTag::corners_board_m`] lists corners in AprilTag's detection order, the
//! tag-frame points `(-s/2, +s/2)`, `(+s/2, +s/2)`, `(+s/2, -s/2)`, `(-s/2, -s/2)` (`s` = tag
//! size, the black border's outer edge): bottom-left, bottom-right, top-right, top-left of the
//! upright tag, counter-clockwise on screen, matching `apriltag_detection_t::p[0..4]`.

use super::family::{TagCells, TagFamily};
pub use super::spec::{BoardAxes, BoardOrigin, BoardSpec, GridSpec, TagPlacementSpec};
use nalgebra::{Isometry3, Point2, Point3, Translation3, Unit, UnitQuaternion, Vector2, Vector3};

mod placement;

use placement::{Layout, PlacedTag};

/// A validation error: the offending key (dotted path inside the board table) and what is wrong.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("`{key}`: {message}")]
pub struct BoardError {
    /// Dotted key path relative to the board table, e.g. `grid.spacing_m` or `tags[2].id`.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

/// One tag on a built board.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardTag {
    /// Tag id.
    pub id: u32,
    /// Tag frame to board frame.
    pub board_from_tag: Isometry3<f64>,
    /// Corners in board frame, AprilTag detection order (see the module doc).
    pub corners_board_m: [Point3<f64>; 4],
    /// Centre in sheet coordinates.
    centre_sheet_m: Vector2<f64>,
    /// In-plane rotation (clockwise seen from the front), radians.
    rotation_rad: f64,
    /// `rotation_rad.sin_cos()`, taken once (the renderer asks for it at every board hit).
    rotation_sin_cos: (f64, f64),
    /// Key path of the spec entry that placed this tag (for error messages).
    key: String,
}

impl BoardTag {
    /// Centre in sheet coordinates (x right, y down from the sheet's top-left corner), metres.
    pub fn centre_sheet_m(&self) -> Vector2<f64> {
        self.centre_sheet_m
    }

    /// In-plane rotation of the printed tag, radians, clockwise as seen from the front.
    pub fn rotation_rad(&self) -> f64 {
        self.rotation_rad
    }
}

/// A ray–board hit, in the frame the ray was given in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardHit {
    /// Ray parameter.
    pub t: f64,
    /// Hit point in board coordinates (z = 0).
    pub point_board_m: Point2<f64>,
    /// Albedo of the print at the hit (back side: the white albedo).
    pub albedo: f32,
    /// Whether the printed side was hit.
    pub front: bool,
}

/// A validated, ready-to-render board in its own board frame.
#[derive(Clone, Debug)]
pub struct Board {
    /// Name from the spec.
    pub name: Option<String>,
    /// Tag family.
    pub family: TagFamily,
    /// Tag size (black border outer edge), metres.
    pub tag_size_m: f64,
    /// Sheet `[width, height]`, metres.
    pub sheet_size_m: [f64; 2],
    /// Albedo of white print.
    pub white_albedo: f32,
    /// Albedo of black print.
    pub black_albedo: f32,
    /// Tags in spec order (grid first, then explicit placements).
    pub tags: Vec<BoardTag>,
    /// Board frame from sheet frame.
    pub board_from_sheet: Isometry3<f64>,
    /// The printed cells of `tags[k]` at index `k` (by index: no lookup per board hit).
    cells_by_tag: Vec<TagCells>,
    /// [`Board::front_normal_board`], computed once from `board_from_sheet` (which nothing
    /// changes after [`Board::from_spec`]).
    front_normal_board: Unit<Vector3<f64>>,
    /// Uniform lookup grid over the sheet: bucket → tag indices.
    buckets: Vec<Vec<u32>>,
    bucket_size_m: f64,
    bucket_dims: [usize; 2],
    /// The printed sheet's raster, when the board is rendered as printed
    /// ([`Board::with_texture`]); `None`: the procedural tag cells.
    texture: Option<super::SheetTexture>,
}

/// The board frame from the sheet frame: the origin moved to the spec's (sheet's top-left
/// corner or centre), then the axes flipped about x for `x_right_y_up`.
fn board_from_sheet(spec: &BoardSpec, sheet_size_m: [f64; 2]) -> Isometry3<f64> {
    let origin = match spec.origin {
        BoardOrigin::SheetTopLeft => Vector3::zeros(),
        BoardOrigin::SheetCentre => Vector3::new(0.5 * sheet_size_m[0], 0.5 * sheet_size_m[1], 0.0),
    };
    let flip = match spec.axes {
        BoardAxes::XRightYDown => UnitQuaternion::identity(),
        BoardAxes::XRightYUp => {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        }
    };
    Isometry3::from_parts(Translation3::identity(), flip)
        * Isometry3::from_parts(Translation3::from(-origin), UnitQuaternion::identity())
}

impl Board {
    /// Validates a spec and builds the board. Errors name the offending key.
    pub fn from_spec(spec: &BoardSpec) -> Result<Self, BoardError> {
        let table = spec.family.code_table();
        let s = spec.tag_size_m;
        let Layout {
            placed,
            sheet_size_m,
            outer_half,
        } = placement::lay_out(spec)?;
        let board_from_sheet = board_from_sheet(spec, sheet_size_m);
        let hs = 0.5 * s;
        let corners_tag = [
            Point3::new(-hs, hs, 0.0),
            Point3::new(hs, hs, 0.0),
            Point3::new(hs, -hs, 0.0),
            Point3::new(-hs, -hs, 0.0),
        ];
        let mut cells_by_tag = Vec::new();
        let tags: Vec<BoardTag> = placed
            .into_iter()
            .map(|placed| {
                let PlacedTag {
                    key,
                    id,
                    centre_sheet_m: c,
                    rotation_rad: rot,
                } = placed;
                let sheet_from_tag = Isometry3::from_parts(
                    Translation3::new(c.x, c.y, 0.0),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rot),
                );
                let board_from_tag = board_from_sheet * sheet_from_tag;
                cells_by_tag.push(
                    table
                        .cells(id)
                        .unwrap_or_else(|| unreachable!("id {id} checked above")),
                );
                BoardTag {
                    id,
                    board_from_tag,
                    corners_board_m: corners_tag.map(|p| board_from_tag * p),
                    centre_sheet_m: c,
                    rotation_rad: rot,
                    rotation_sin_cos: rot.sin_cos(),
                    key,
                }
            })
            .collect();
        let front_normal_board =
            Unit::new_normalize(board_from_sheet.transform_vector(&-Vector3::z()));
        let mut board = Self {
            name: spec.name.clone(),
            family: spec.family,
            tag_size_m: s,
            sheet_size_m,
            white_albedo: spec.white_albedo as f32,
            black_albedo: spec.black_albedo as f32,
            tags,
            board_from_sheet,
            cells_by_tag,
            front_normal_board,
            buckets: Vec::new(),
            bucket_size_m: 2.0 * outer_half,
            bucket_dims: [0, 0],
            texture: None,
        };
        board.build_buckets(outer_half);
        Ok(board)
    }

    /// Fills the lookup grid over the sheet: every bucket that the bounding box of a tag's
    /// square of half-side `outer_half` (the tag with its quiet zone) touches lists that tag.
    fn build_buckets(&mut self, outer_half: f64) {
        let size = self.bucket_size_m;
        // Guard: at most a few hundred thousand buckets even for tiny tags on a big sheet.
        let nx = ((self.sheet_size_m[0] / size).ceil() as usize).clamp(1, 512);
        let ny = ((self.sheet_size_m[1] / size).ceil() as usize).clamp(1, 512);
        let (bx, by) = (
            self.sheet_size_m[0] / nx as f64,
            self.sheet_size_m[1] / ny as f64,
        );
        self.bucket_dims = [nx, ny];
        self.buckets = vec![Vec::new(); nx * ny];
        for (k, t) in self.tags.iter().enumerate() {
            let r = outer_half * (t.rotation_rad.cos().abs() + t.rotation_rad.sin().abs());
            let lo = t.centre_sheet_m - Vector2::repeat(r);
            let hi = t.centre_sheet_m + Vector2::repeat(r);
            let x0 = ((lo.x / bx).floor().max(0.0) as usize).min(nx - 1);
            let x1 = ((hi.x / bx).floor().max(0.0) as usize).min(nx - 1);
            let y0 = ((lo.y / by).floor().max(0.0) as usize).min(ny - 1);
            let y1 = ((hi.y / by).floor().max(0.0) as usize).min(ny - 1);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    self.buckets[y * nx + x].push(k as u32);
                }
            }
        }
    }

    /// The same board with its print taken from `texture` (a rasterised print of this sheet,
    /// see [`super::texture`]) instead of the procedural tag cells; tag geometry is unchanged.
    pub fn with_texture(mut self, texture: super::SheetTexture) -> Self {
        self.texture = Some(texture);
        self
    }

    /// Whether the board is rendered from a print's raster.
    pub fn is_textured(&self) -> bool {
        self.texture.is_some()
    }

    /// The tag with this id, if the board has it.
    pub fn tag(&self, id: u32) -> Option<&BoardTag> {
        self.tags.iter().find(|t| t.id == id)
    }

    /// The printed cells of tag `id` (its code, black border and white outer ring).
    pub fn tag_cells(&self, id: u32) -> Option<&TagCells> {
        let k = self.tags.iter().position(|t| t.id == id)?;
        Some(&self.cells_by_tag[k])
    }

    /// Corners of tag `id` in board frame, AprilTag detection order (see the module doc).
    pub fn tag_corners_board_m(&self, id: u32) -> Option<[Point3<f64>; 4]> {
        self.tag(id).map(|t| t.corners_board_m)
    }

    /// Key path of the spec entry that placed tag index `k` (for scene-level error messages).
    pub fn tag_key(&self, k: usize) -> Option<&str> {
        self.tags.get(k).map(|t| t.key.as_str())
    }

    /// Whether a board-plane point lies on the sheet.
    pub fn contains(&self, point_board_m: &Point2<f64>) -> bool {
        self.sheet_contains(&self.sheet_point(point_board_m))
    }

    /// [`Board::contains`] of a point already in sheet coordinates.
    fn sheet_contains(&self, p: &Point2<f64>) -> bool {
        (0.0..=self.sheet_size_m[0]).contains(&p.x) && (0.0..=self.sheet_size_m[1]).contains(&p.y)
    }

    fn sheet_point(&self, point_board_m: &Point2<f64>) -> Point2<f64> {
        let p = self.board_from_sheet.inverse_transform_point(&Point3::new(
            point_board_m.x,
            point_board_m.y,
            0.0,
        ));
        Point2::new(p.x, p.y)
    }

    /// Printed albedo at a board-plane point: black or white print; the quiet zone and the rest of
    /// the sheet (and anything off the sheet) are white.
    pub fn albedo_at(&self, point_board_m: &Point2<f64>) -> f32 {
        self.albedo_at_sheet(&self.sheet_point(point_board_m))
    }

    /// [`Board::albedo_at`] of a point already in sheet coordinates.
    fn albedo_at_sheet(&self, p: &Point2<f64>) -> f32 {
        let [nx, ny] = self.bucket_dims;
        if !(p.x >= 0.0 && p.y >= 0.0 && p.x < self.sheet_size_m[0] && p.y < self.sheet_size_m[1]) {
            return self.white_albedo;
        }
        if let Some(t) = &self.texture {
            let g = t.gray_at(p.x / self.sheet_size_m[0], p.y / self.sheet_size_m[1]) as f32;
            return self.black_albedo + (self.white_albedo - self.black_albedo) * g;
        }
        let bx = ((p.x / self.sheet_size_m[0] * nx as f64) as usize).min(nx - 1);
        let by = ((p.y / self.sheet_size_m[1] * ny as f64) as usize).min(ny - 1);
        let table = self.family.code_table();
        let cell = self.tag_size_m / table.width_at_border as f64;
        let total = table.total_width as f64 * cell;
        for &k in &self.buckets[by * nx + bx] {
            let t = &self.tags[k as usize];
            let d = p.coords - t.centre_sheet_m;
            // Rotate into the tag frame (inverse of the clockwise-seen-from-front rotation).
            let (sin, cos) = t.rotation_sin_cos;
            let local = Vector2::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y);
            let u = (local.x + 0.5 * total) / cell;
            let v = (local.y + 0.5 * total) / cell;
            if u >= 0.0 && v >= 0.0 && u < table.total_width as f64 && v < table.total_width as f64
            {
                let white = self.cells_by_tag[k as usize].is_white(u as usize, v as usize);
                return if white {
                    self.white_albedo
                } else {
                    self.black_albedo
                };
            }
        }
        self.white_albedo
    }

    /// Unit normal of the printed side in board frame (`-z` for y-down axes, `+z` for y-up).
    #[inline]
    pub fn front_normal_board(&self) -> Unit<Vector3<f64>> {
        self.front_normal_board
    }

    /// Ray (in board frame) against the sheet rectangle; both sides are solid.
    pub fn intersect(
        &self,
        ray: &crate::geometry::Ray,
        t_min: f64,
        t_max: f64,
    ) -> Option<BoardHit> {
        // Guard: a ray parallel to the sheet never hits it.
        if ray.dir.z == 0.0 {
            return None;
        }
        let t = -ray.origin.z / ray.dir.z;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let p = ray.at(t);
        let point = Point2::new(p.x, p.y);
        let sheet = self.sheet_point(&point);
        if !self.sheet_contains(&sheet) {
            return None;
        }
        let front = ray.dir.dot(&self.front_normal_board) < 0.0;
        let albedo = if front {
            self.albedo_at_sheet(&sheet)
        } else {
            self.white_albedo
        };
        Some(BoardHit {
            t,
            point_board_m: point,
            albedo,
            front,
        })
    }
}
