//! AprilTag boards (placeholder while the module is written).
