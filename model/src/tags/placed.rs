//! A [`Board`] posed in the world: world-space ray hits and world-space tag corners.
//!
//! Contract: `world_from_board` maps the board frame (see [`super::board`]) into the world; hits
//! report the world-space ray parameter (unchanged by the rigid transform), the board-plane point,
//! the print albedo and the world normal of the side that was hit's printed face.

use super::{Board, BoardHit};
use crate::geometry::Ray;
use nalgebra::{Isometry3, Point3, Unit, Vector3};

/// A board with its pose in the world.
#[derive(Clone, Debug)]
pub struct PlacedBoard {
    /// The board in its own frame.
    pub board: Board,
    /// Board frame to world frame.
    pub world_from_board: Isometry3<f64>,
}

impl PlacedBoard {
    /// Intersects a world-space ray with the sheet.
    #[inline]
    pub fn intersect(&self, ray_world: &Ray, t_min: f64, t_max: f64) -> Option<BoardHit> {
        let ray_board = Ray::new(
            self.world_from_board
                .inverse_transform_point(&ray_world.origin),
            self.world_from_board
                .inverse_transform_vector(&ray_world.dir),
        );
        self.board.intersect(&ray_board, t_min, t_max)
    }

    /// World normal of the printed face.
    pub fn front_normal_world(&self) -> Unit<Vector3<f64>> {
        self.world_from_board * self.board.front_normal_board()
    }

    /// World-space corners of tag `id` in AprilTag detection order.
    pub fn tag_corners_world_m(&self, id: u32) -> Option<[Point3<f64>; 4]> {
        self.board
            .tag_corners_board_m(id)
            .map(|c| c.map(|p| self.world_from_board * p))
    }
}
