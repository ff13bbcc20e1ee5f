//! `ddct bench`: plant + TCU + driver scenario on a bus, with a summary (issue 6).

use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct BenchArgs {}

pub fn run(_args: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct bench` is not implemented yet")
}
