//! `ellipso session upgrade DIR`: gives a session recorded before sessions carried their whole
//! rig record that record ([`ellipso_capture::session_upgrade::upgrade`], whose doc states the
//! contract); the binary keeps the flags and says what was done.

use std::path::PathBuf;

/// `ellipso session …`.
#[derive(Debug, clap::Subcommand)]
pub enum Args {
    /// Write the rig record (radiometry, noise) a session recorded by an older ellipso lacks,
    /// from the scene file it names; the old manifest is kept as manifest.json.pre-upgrade.
    Upgrade(UpgradeArgs),
}

/// Arguments of `ellipso session upgrade`.
#[derive(Debug, clap::Args)]
pub struct UpgradeArgs {
    /// Session directory.
    pub session: PathBuf,
}

/// Runs `ellipso session …`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args {
        Args::Upgrade(a) => {
            match ellipso_capture::session_upgrade::upgrade(&a.session)
                .map_err(super::out::failed)?
            {
                Some(backup) => crate::outln!(
                    "{}: rig record written; the old manifest is {}",
                    a.session.display(),
                    backup.display()
                ),
                None => crate::outln!(
                    "{}: already carries its rig record; nothing to do",
                    a.session.display()
                ),
            }
            Ok(())
        }
    }
}
