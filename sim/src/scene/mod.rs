//! Scene description files (TOML): objects, materials, AprilTag boards, rig and capture path.
