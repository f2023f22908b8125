//! Polarisation-mosaic processing for Sony IMX250MZR/MYR-class sensors.
