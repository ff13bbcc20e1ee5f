//! `ddct model`: evaluate and plot the physics (issue 4).

use clap::Subcommand;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum ModelCmd {
    /// Torque of the clutch characteristic (13).
    Torque,
}

pub fn run(_cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct model` is not implemented yet")
}
