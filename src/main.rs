//! `ddct`: parses the command line and hands validated configurations to the library.

mod cli;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Virtual TCU, plant and sim-to-real gap diagnosis for a dry dual-clutch transmission on CAN.
#[derive(Debug, Parser)]
#[command(name = "ddct", version, about, long_about = None)]
struct Cli {
    /// Log filter for diagnostics on stderr (tracing syntax, e.g. `info`, `ddct=debug`).
    #[arg(long, global = true, default_value = "warn", env = "DDCT_LOG")]
    log_level: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Read, decode, record and replay candump logs.
    #[command(subcommand)]
    Log(cli::log::LogCmd),
    /// Inspect the bus contract (dbc/ddct.dbc).
    #[command(subcommand)]
    Dbc(cli::dbc::DbcCmd),
    /// Evaluate and plot the physics models.
    #[command(subcommand)]
    Model(cli::model::ModelCmd),
    /// Run the plant daemon: the simulated dual-clutch transmission on a bus.
    Plant(cli::plant::PlantArgs),
    /// Run the virtual TCU daemon on a bus.
    Tcu(cli::tcu::TcuArgs),
    /// Run plant and TCU cores in lockstep, faster than real time.
    Sim(cli::sim::SimArgs),
    /// Identify torque and thermal parameters from bench data.
    Identify(cli::gap::IdentifyArgs),
    /// Sim-to-real gap diagnosis.
    #[command(subcommand)]
    Gap(cli::gap::GapCmd),
    /// Run the bench: plant and TCU daemons and a driver scenario, then print a summary.
    Bench(cli::bench::BenchArgs),
    /// UDS tester of the TCU (DIDs, fault memory, kiss-point routine, calibration) and its A2L.
    #[command(subcommand)]
    Diag(cli::diag::DiagCmd),
}

fn main() -> ExitCode {
    // Behave like other Unix filters when the reader of stdout goes away (`ddct ... | head`).
    // SAFETY: resetting a signal disposition to its default before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    cli::init_tracing(&cli.log_level);
    let result = match cli.command {
        Command::Log(c) => cli::log::run(c),
        Command::Dbc(c) => cli::dbc::run(c),
        Command::Model(c) => cli::model::run(c),
        Command::Plant(a) => cli::plant::run(a),
        Command::Tcu(a) => cli::tcu::run(a),
        Command::Diag(c) => cli::diag::run(c),
        Command::Sim(a) => cli::sim::run(a),
        Command::Identify(a) => cli::gap::run_identify(a),
        Command::Gap(c) => cli::gap::run(c),
        Command::Bench(a) => cli::bench::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
