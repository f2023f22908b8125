//! `ellipso-protocol`: the wire contract between the trigger board and the host.
#![no_std]
