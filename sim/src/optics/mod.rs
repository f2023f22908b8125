//! Polarimetric optics: the model the simulator renders with and the fit inverts.
