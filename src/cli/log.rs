//! `ddct log`: decode, record and replay candump logs.

use clap::Subcommand;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum LogCmd {
    /// Decode a candump -l log with the DBC.
    Decode,
}

pub fn run(_cmd: LogCmd) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct log` is not implemented yet")
}
