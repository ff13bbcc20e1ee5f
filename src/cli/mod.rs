//! Subcommand wiring for the `ddct` binary: each module turns raw arguments into a validated
//! configuration and calls the library. `anyhow` lives here and nowhere else.

pub mod args;
pub mod bench;
pub mod dbc;
pub mod gap;
pub mod log;
pub mod model;
pub mod plant;
pub mod sim;
pub mod tcu;

use anyhow::Context as _;

/// Installs the stderr diagnostics subscriber.
pub fn init_tracing(filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_new(filter)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

/// A single-threaded tokio runtime with I/O and timers.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

/// Listens for SIGINT and SIGTERM from this call on (the handlers are installed now, not when
/// the future is first polled, so a signal sent right after a daemon says it is ready is not
/// lost); the future resolves on the first. Call it inside the runtime.
pub fn shutdown_signal() -> impl std::future::Future<Output = ()> {
    use tokio::signal::unix::{signal, SignalKind};
    let term = signal(SignalKind::terminate()).ok();
    let int = signal(SignalKind::interrupt()).ok();
    async move {
        let wait = |s: Option<tokio::signal::unix::Signal>| async move {
            match s {
                Some(mut s) => {
                    s.recv().await;
                }
                None => std::future::pending::<()>().await,
            }
        };
        tokio::select! {
            _ = wait(int) => {}
            _ = wait(term) => {}
        }
    }
}

/// Tells a bench script that the daemon listens: writes its pid to `path` (through a temporary
/// file renamed into place, so a reader never sees it half written). Call it once the socket is
/// open with its filters and the signal handlers are installed.
pub fn announce_ready(path: Option<&std::path::Path>) -> anyhow::Result<()> {
    let Some(path) = path else { return Ok(()) };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, format!("{}\n", std::process::id()))
        .and_then(|()| std::fs::rename(&tmp, path))
        .with_context(|| format!("--ready-file {}", path.display()))
}
