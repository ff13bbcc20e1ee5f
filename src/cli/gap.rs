//! `ddct identify` and `ddct gap`: parameter identification and sim-to-real diagnosis (issue 7).

use clap::{Args, Subcommand};
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct IdentifyArgs {}

#[derive(Debug, Subcommand)]
pub enum GapCmd {
    /// Diagnose the gap between a model and bench data.
    Diagnose,
}

pub fn run_identify(_args: IdentifyArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct identify` is not implemented yet")
}

pub fn run(_cmd: GapCmd) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct gap` is not implemented yet")
}
