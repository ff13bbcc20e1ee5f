//! Subcommand wiring for the `ddct` binary: each module turns raw arguments into a validated
//! configuration and calls the library. `anyhow` lives here and nowhere else.

pub mod bench;
pub mod dbc;
pub mod gap;
pub mod log;
pub mod model;
pub mod plant;
pub mod sim;
pub mod tcu;

/// Installs the stderr diagnostics subscriber.
pub fn init_tracing(filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_new(filter)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
