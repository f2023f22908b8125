//! Why a mesh cannot be built from a session, each naming the cause and the frames involved.

use ellipso_fit::observe::SkippedFrame;

/// Errors of [`super::build_mesh`].
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The session lacks what the carving needs (camera, boards, flash, scene file).
    #[error("{0}")]
    Session(String),
    /// Too few frames have a pose (and a readable image) to carve from.
    #[error(
        "only {usable} posed frames can be used (at least {needed} are needed to carve a hull \
         with {votes} votes per voxel): posed and usable: {posed}; not usable: {unusable}; \
         tracking rejected: {rejected}"
    )]
    TooFewPosedFrames {
        /// Usable posed frames.
        usable: usize,
        /// Needed.
        needed: usize,
        /// Votes per voxel.
        votes: usize,
        /// The usable posed frames.
        posed: String,
        /// Posed frames that could not be used, with reasons.
        unusable: String,
        /// Frames whose pose tracking was rejected, with reasons.
        rejected: String,
    },
    /// The hull reaches a face of the volume above the board.
    #[error(
        "the object is not inside the board's footprint: its hull reaches the {faces} face(s) of \
         the volume above board {board} (x {x0:.3}…{x1:.3} m, y {y0:.3}…{y1:.3} m, height \
         {height:.3} m); it is seen there in frames {frames}. Place the object on the board, \
         inside its tags, and no taller than the board is wide"
    )]
    ObjectOffBoard {
        /// Faces reached.
        faces: String,
        /// Board index.
        board: usize,
        /// Footprint, volume frame.
        x0: f64,
        /// Footprint.
        x1: f64,
        /// Footprint.
        y0: f64,
        /// Footprint.
        y1: f64,
        /// Box height.
        height: f64,
        /// Frames that see that part.
        frames: String,
    },
    /// Nothing was left after carving.
    #[error(
        "the hull is empty: in {views} frames ({frames}) every voxel above board {board} was seen \
         as bare board by at least {votes} frames; no object stands on the board, or it looks \
         exactly like the board"
    )]
    HullEmpty {
        /// Board index.
        board: usize,
        /// Views used.
        views: usize,
        /// Their ids.
        frames: String,
        /// Votes per voxel.
        votes: usize,
    },
    /// The hull falls into separate parts.
    #[error(
        "the hull is disconnected: besides the main part ({main_cm3:.1} cm³ at {main_at}) there \
         is a separate part of {second_cm3:.1} cm³ at {second_at} (board frame, mm), seen in \
         frames {frames}; carve one object at a time, or check those frames for something \
         standing on the board"
    )]
    HullDisconnected {
        /// Main part volume, cm³.
        main_cm3: f64,
        /// Main part centroid.
        main_at: String,
        /// Second part volume, cm³.
        second_cm3: f64,
        /// Second part centroid.
        second_at: String,
        /// Frames that see the second part.
        frames: String,
    },
    /// The hull reaches out of the box or falls apart where the views that see it all look from
    /// one side (`crate::coverage`): the capture lacks views there, not the object's placement.
    #[error(
        "the hull {what}, where too few views constrain it: {why}; frames {frames}. The object \
         may well be on the board and alone: {advice}"
    )]
    UnderViewed {
        /// What the hull does there.
        what: String,
        /// What the views lack (`Coverage::describe`).
        why: String,
        /// What to photograph (`Coverage::advice`).
        advice: String,
        /// The frames that see it.
        frames: String,
    },
    /// The extracted surface is not a closed manifold or not a valid mesh (a bug, reported).
    #[error("surface extraction failed: {0}")]
    Surface(String),
}

/// `a, b, c, … (n frames)`, at most `max` ids shown.
pub fn frame_list(ids: &[u64], max: usize) -> String {
    if ids.is_empty() {
        return "none".into();
    }
    let shown: Vec<String> = ids.iter().take(max).map(u64::to_string).collect();
    if ids.len() > max {
        format!("{}, … ({} frames)", shown.join(", "), ids.len())
    } else {
        shown.join(", ")
    }
}

/// `id (reason); …`, at most `max` shown.
pub fn skipped_list(skipped: &[SkippedFrame], max: usize) -> String {
    if skipped.is_empty() {
        return "none".into();
    }
    let shown: Vec<String> = skipped
        .iter()
        .take(max)
        .map(|s| format!("{} ({})", s.frame_id, s.reason))
        .collect();
    if skipped.len() > max {
        format!("{}; … ({} frames)", shown.join("; "), skipped.len())
    } else {
        shown.join("; ")
    }
}
