//! `ddct tcu`: the TCU daemon (issue 6).

use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct TcuArgs {}

pub fn run(_args: TcuArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct tcu` is not implemented yet")
}
