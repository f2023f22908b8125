//! Cross-module tests of the optics model.
