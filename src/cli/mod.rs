//! Subcommand wiring for the `ddct` binary: each module turns raw arguments into a validated
//! configuration and calls the library. `anyhow` lives here and nowhere else.

pub mod args;
pub mod bench;
pub mod dbc;
pub mod diag;
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
    use std::io::IsTerminal as _;
    // Colour only for a terminal: a piped or redirected stderr gets plain text.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
}

/// A single-threaded tokio runtime with I/O and timers.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    ddct::daemon::runtime().context("starting the async runtime")
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

/// Peak resident memory of this process (VmHWM of /proc/self/status, MiB); `None` where there
/// is no such file. Unlike getrusage's ru_maxrss it does not carry the parent's memory across
/// exec, so a benchmark driver can read it from the child's report.
pub fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// A spinner with the elapsed time for a step that takes longer than a few seconds (`msg` says
/// what runs); drawn on stderr only when it is a terminal (indicatif hides it otherwise).
pub fn spinner(msg: impl Into<std::borrow::Cow<'static, str>>) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new_spinner().with_message(msg);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    // The ticking thread only where the spinner shows (indicatif hides it off a terminal).
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        pb.enable_steady_tick(std::time::Duration::from_millis(200));
    }
    pb
}

/// A bar over `len` steps of `unit` with the elapsed time and the time left; terminal only.
pub fn bar(len: u64, unit: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len);
    let template =
        format!("[{{bar:30}}] {{pos}}/{{len}} {unit}{{msg}}, {{elapsed}} elapsed, ~{{eta}} left");
    pb.set_style(
        indicatif::ProgressStyle::with_template(&template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb
}

/// A bar over `len` bytes of input (a file being read) with the time left; terminal only.
pub fn byte_bar(
    len: u64,
    msg: impl Into<std::borrow::Cow<'static, str>>,
) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len).with_message(msg);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg} [{bar:30}] {bytes}/{total_bytes}, {elapsed} elapsed, ~{eta} left",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    pb
}

/// A spinner with a count of `unit` (advanced by `inc`) and the elapsed time, for input of
/// unknown length such as standard input; terminal only.
pub fn counter(
    msg: impl Into<std::borrow::Cow<'static, str>>,
    unit: &str,
) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new_spinner().with_message(msg);
    let template = format!("{{spinner}} {{msg}}: {{pos}} {unit} ({{elapsed}})");
    pb.set_style(
        indicatif::ProgressStyle::with_template(&template)
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    pb
}
