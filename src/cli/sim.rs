//! `ddct sim`: plant and TCU cores in lockstep (issue 6).

use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct SimArgs {}

pub fn run(_args: SimArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct sim` is not implemented yet")
}
