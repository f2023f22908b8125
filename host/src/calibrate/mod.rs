//! Camera calibration (in progress).
