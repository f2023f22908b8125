//! `ellipso-firmware`: the trigger board's hardware-independent sync core.
#![cfg_attr(not(test), no_std)]
