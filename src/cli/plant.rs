//! `ddct plant`: the plant daemon (issue 5).

use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct PlantArgs {}

pub fn run(_args: PlantArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("`ddct plant` is not implemented yet")
}
