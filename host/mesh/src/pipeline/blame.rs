//! Which frames to name when the hull is rejected: the views in which a point projects inside
//! the image, [`MeshError::UnderViewed`] when those views leave the far side of the part unseen
//! (the capture is short of views there, `crate::coverage`), and [`MeshError::ObjectOffBoard`]
//! for a part that reaches a face of the volume.
//!
//! Contract: errors name frames by id (at most 10 listed); a point is judged at the part's
//! centre, not at the box's edge, so a short capture is told apart from a misplaced object.

use nalgebra::Point3;

use crate::carve::Grid;
use crate::components::{self, Part};
use crate::coverage::coverage;
use crate::error::frame_list;
use crate::silhouette::Silhouette;
use crate::{MeshConfig, MeshError};

use super::Setup;

/// The views in which `p` (volume frame) projects inside the image.
pub(super) fn frames_seeing(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    p: Point3<f64>,
) -> Vec<u64> {
    views_seeing(setup, silhouettes, p)
        .map(|i| setup.views[i].frame_id)
        .collect()
}

/// Indices into `setup.views` of the views in which `p` projects inside the image.
fn views_seeing<'s>(
    setup: &'s Setup<'_>,
    silhouettes: &'s [(usize, Silhouette)],
    p: Point3<f64>,
) -> impl Iterator<Item = usize> + 's {
    silhouettes
        .iter()
        .filter(move |(i, _)| {
            let c = setup.views[*i].camera_from_volume * p;
            setup
                .camera
                .project(&c)
                .is_some_and(|px| setup.camera.contains_pixel(px))
        })
        .map(|(i, _)| *i)
}

/// [`MeshError::UnderViewed`] for the hull's `what`, when the views that see `p` (a part's
/// centre) leave its far side unseen (`crate::coverage`): the capture is short of views there, whatever the
/// object's placement.
pub(super) fn under_viewed(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    p: Point3<f64>,
    what: String,
    votes: usize,
) -> Option<MeshError> {
    let seeing: Vec<usize> = views_seeing(setup, silhouettes, p).collect();
    let cover = coverage(p, seeing.iter().map(|&i| setup.views[i].centre));
    cover.one_sided(votes).then(|| {
        let ids: Vec<u64> = seeing.iter().map(|&i| setup.views[i].frame_id).collect();
        MeshError::UnderViewed {
            what,
            why: cover.describe(votes),
            advice: cover.advice().to_string(),
            frames: frame_list(&ids, 10),
        }
    })
}

/// [`MeshError::ObjectOffBoard`] for `main` reaching the box faces `faces` (indices into
/// [`components::FACES`]), naming the frames that see the main part's edge on the first of them;
/// [`MeshError::UnderViewed`] instead when those frames leave that edge's far side unseen.
pub(super) fn off_board(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    grid: &Grid,
    main: &Part,
    faces: &[usize],
    config: &MeshConfig,
) -> MeshError {
    let face = faces[0];
    let axis = face / 2;
    let ijk: [usize; 3] = std::array::from_fn(|a| match a {
        a if a == axis && face % 2 == 0 => main.min[a],
        a if a == axis => main.max[a],
        a => (main.min[a] + main.max[a]) / 2,
    });
    let (lo, hi) = (setup.volume.min_m, setup.volume.max_m);
    let face_names = faces
        .iter()
        .map(|&f| components::FACES[f])
        .collect::<Vec<_>>()
        .join(", ");
    let what = format!(
        "reaches the {face_names} face(s) of the volume above board {}",
        setup.volume.board
    );
    // judged at the object's centre, not at the face: a point at the box's edge is out of the
    // nearest views' images whatever the capture
    if let Some(e) = under_viewed(
        setup,
        silhouettes,
        components::centroid(main),
        what,
        config.votes,
    ) {
        return e;
    }
    MeshError::ObjectOffBoard {
        faces: face_names,
        board: setup.volume.board,
        x0: lo.x,
        x1: hi.x,
        y0: lo.y,
        y1: hi.y,
        height: hi.z,
        frames: frame_list(&frames_seeing(setup, silhouettes, grid.point(ijk)), 10),
    }
}
