//! `ddct dbc`: show the bus contract.

use clap::Subcommand;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum DbcCmd {
    /// List the messages of the contract.
    Show,
}

pub fn run(_cmd: DbcCmd) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct dbc` is not implemented yet")
}
