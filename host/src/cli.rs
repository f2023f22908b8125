//! The `ellipso` command line: one module per subcommand, each with an `Args` (clap) and a `run`.

pub mod allocator;
pub mod bench;
pub mod board;
pub mod calibrate;
pub mod capture;
pub mod demo;
pub mod devices;
pub mod export;
pub mod fit;
pub mod fit_import;
pub mod fit_shard;
pub mod interrupt;
pub mod limits;
pub mod mesh;
pub mod model;
pub mod out;
pub mod polar;
pub mod progress;
pub mod record;
pub mod replay;
pub mod rig;
pub mod session;
pub mod sim;
pub mod sim_serve;
pub mod view;
