//! The `ellipso` command line: one module per subcommand, each with an `Args` (clap) and a `run`.

pub mod model;
pub mod polar;
pub mod sim_serve;
