//! Argument types parsed at the boundary (clap `value_parser`s): the bus a daemon runs on, the
//! pace of a simulation, a real-time priority; and opening a CAN interface with a hint on how to
//! get one when it does not exist.

use ddct::can::socketcan::SocketCanBus;
use std::fmt;
use std::str::FromStr;

/// `--iface`: a SocketCAN interface, or `sim` for the in-process bus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Iface {
    /// The in-process bus (no CAN needed).
    Sim,
    /// A SocketCAN interface such as vcan0.
    Can(String),
}

impl Iface {
    pub fn is_sim(&self) -> bool {
        matches!(self, Iface::Sim)
    }
}

impl FromStr for Iface {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "sim" {
            return Ok(Iface::Sim);
        }
        // Linux interface names: 1..=15 bytes (IFNAMSIZ − 1), no '/', ':' or whitespace.
        let ok = !s.is_empty()
            && s.len() <= 15
            && s.bytes()
                .all(|b| b.is_ascii_graphic() && b != b'/' && b != b':');
        if ok {
            Ok(Iface::Can(s.to_string()))
        } else {
            Err(format!(
                "{s:?} is not a network interface name (1 to 15 characters, no '/', ':' or \
                 spaces), nor `sim` for the in-process bus"
            ))
        }
    }
}

impl fmt::Display for Iface {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Iface::Sim => f.write_str("sim"),
            Iface::Can(s) => f.write_str(s),
        }
    }
}

/// Where `ddct log monitor` reads, given positionally as candump takes it: standard input
/// (`-`), a log file that exists, or a network interface that exists (`vcan0`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Source {
    Stdin,
    File(std::path::PathBuf),
    Iface(String),
}

impl Source {
    /// Resolves a positional argument: `-`, then an existing file, then an existing network
    /// interface; anything else is an error that says it is neither.
    pub fn resolve(arg: &std::ffi::OsStr) -> Result<Self, String> {
        if arg == "-" {
            return Ok(Source::Stdin);
        }
        let path = std::path::Path::new(arg);
        if path.is_file() {
            return Ok(Source::File(path.to_path_buf()));
        }
        let text = arg.to_string_lossy();
        if let Ok(Iface::Can(name)) = text.parse::<Iface>() {
            if iface_exists(&name) {
                return Ok(Source::Iface(name));
            }
            return Err(format!(
                "{text}: neither a log file nor a network interface of this machine (to create \
                 vcan {text} as root: `ip link add dev {text} type vcan && ip link set up \
                 {text}`; where the kernel has no CAN: `scripts/vcan-run ddct ...`)"
            ));
        }
        Err(format!("{text}: no such log file (nor an interface name)"))
    }
}

/// A network interface that exists (`/sys/class/net/NAME`), whatever its type.
pub fn iface_exists(name: &str) -> bool {
    std::path::Path::new("/sys/class/net").join(name).exists()
}

/// `ddct log record IFACE`: a CAN interface name (positional, like candump); a path (a `/` in
/// it) or `sim` is refused with what the command wants.
pub fn can_iface(s: &str) -> Result<String, String> {
    match s.parse::<Iface>() {
        Ok(Iface::Can(name)) => Ok(name),
        Ok(Iface::Sim) => Err("sim: recording needs a SocketCAN interface such as vcan0".into()),
        Err(_) => Err(format!(
            "{s:?} is not a CAN interface name such as vcan0 (the log file is --out FILE)"
        )),
    }
}

/// `--speed` of a simulation: a factor of real time, or `max` (as fast as the host computes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    Max,
    Factor(f64),
}

impl FromStr for Speed {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "max" {
            return Ok(Speed::Max);
        }
        match s.parse::<f64>() {
            Ok(k) if k > 0.0 && k <= 1000.0 => Ok(Speed::Factor(k)),
            _ => Err(format!("{s}: a factor of real time in (0, 1000], or `max`")),
        }
    }
}

/// A positive, finite number of seconds (`--duration`, `--lockstep-timeout`).
pub fn seconds(s: &str) -> Result<std::time::Duration, String> {
    match s.parse::<f64>() {
        Ok(d) if d.is_finite() && d > 0.0 && d < 1e9 => Ok(std::time::Duration::from_secs_f64(d)),
        _ => Err(format!("{s}: a positive number of seconds")),
    }
}

/// A parser of a finite number in `lo ..= hi` of `unit` (`--echo`, `--input-speed`).
pub fn number_in(
    lo: f64,
    hi: f64,
    unit: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!("{s}: a number of {unit} in {lo} ..= {hi}")),
    }
}

/// `--rt-priority`: SCHED_FIFO priorities are 1..=99; anything else is refused, not clamped.
pub fn rt_priority(s: &str) -> Result<i32, String> {
    let r = ddct::daemon::os::RT_PRIORITIES;
    match s.parse::<i32>() {
        Ok(p) if r.contains(&p) => Ok(p),
        _ => Err(format!(
            "{s}: a SCHED_FIFO priority in {}..={}",
            r.start(),
            r.end()
        )),
    }
}

/// `--nice`: the CFS nice values are -20..=19 (lower is more CPU); anything else is refused.
pub fn nice_value(s: &str) -> Result<i32, String> {
    let r = ddct::daemon::os::NICE_VALUES;
    match s.parse::<i32>() {
        Ok(n) if r.contains(&n) => Ok(n),
        _ => Err(format!("{s}: a nice value in {}..={}", r.start(), r.end())),
    }
}

/// The TCU calibration of `--config`, or the built-in `config/tcu.toml` (with the built-in
/// `config/params.toml`) without one: the commands work from any directory.
pub fn tcu_config(path: Option<&std::path::Path>) -> anyhow::Result<ddct::tcu::TcuConfig> {
    use anyhow::Context as _;
    match path {
        Some(p) => ddct::tcu::TcuConfig::load(p).context("loading the TCU calibration"),
        None => Ok(ddct::tcu::TcuConfig::default()),
    }
}

/// Opens a SocketCAN interface on the current tokio runtime; when it does not exist, says how
/// to get one.
pub fn open_can(iface: &str) -> anyhow::Result<SocketCanBus> {
    SocketCanBus::open(iface, false).map_err(|e| can_error(iface, e))
}

/// Checks that a SocketCAN interface exists, without a runtime (a blocking socket closed at
/// once): for a command that opens its endpoints later, on threads of their own.
pub fn probe_can(iface: &str) -> anyhow::Result<()> {
    SocketCanBus::probe(iface).map_err(|e| can_error(iface, e))
}

/// A bus error for the user: a missing interface with how to create one.
fn can_error(iface: &str, e: ddct::can::BusError) -> anyhow::Error {
    let missing = std::error::Error::source(&e)
        .and_then(|s| s.downcast_ref::<std::io::Error>())
        .and_then(std::io::Error::raw_os_error)
        == Some(libc::ENODEV);
    if missing {
        anyhow::anyhow!(
            "CAN interface {iface} does not exist. Create a virtual one (as root): `ip link \
             add dev {iface} type vcan && ip link set up {iface}` (needs the vcan module), \
             or run the command inside `scripts/vcan-run` (User-Mode Linux with vcan0 up), \
             or use `--iface sim` for the in-process bus where the command has it"
        )
    } else {
        anyhow::Error::new(e).context(format!("opening CAN interface {iface}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ifaces_parse_to_sim_or_a_valid_name() {
        assert_eq!("sim".parse::<Iface>(), Ok(Iface::Sim));
        assert_eq!(seconds("2.5"), Ok(std::time::Duration::from_millis(2500)));
        for bad in ["0", "-1", "nan", "inf", "x"] {
            assert!(seconds(bad)
                .unwrap_err()
                .contains("positive number of seconds"));
        }
        let rpm = number_in(0.0, 6000.0, "rpm");
        assert_eq!(rpm("6000"), Ok(6000.0));
        for bad in ["-0.1", "6000.5", "NaN", "fast"] {
            assert!(rpm(bad).unwrap_err().contains("rpm in 0 ..= 6000"), "{bad}");
        }
        assert_eq!("vcan0".parse::<Iface>(), Ok(Iface::Can("vcan0".into())));
        for bad in ["", "a/b", "can 0", "x:1", "sixteen_chars_xx"] {
            assert!(bad.parse::<Iface>().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn positional_sources_are_stdin_a_file_or_an_existing_interface() {
        use std::ffi::OsStr;
        assert_eq!(Source::resolve(OsStr::new("-")), Ok(Source::Stdin));
        let f = std::env::temp_dir().join(format!("ddct-src-{}.log", std::process::id()));
        std::fs::write(&f, "").unwrap();
        assert_eq!(Source::resolve(f.as_os_str()), Ok(Source::File(f.clone())));
        std::fs::remove_file(&f).unwrap();
        // `lo` exists on every Linux machine (a network interface, if not a CAN one).
        assert_eq!(
            Source::resolve(OsStr::new("lo")),
            Ok(Source::Iface("lo".into()))
        );
        let e = Source::resolve(OsStr::new("vcan97")).unwrap_err();
        assert!(
            e.contains("neither a log file nor a network interface"),
            "{e}"
        );
        let e = Source::resolve(OsStr::new("no/such/file.log")).unwrap_err();
        assert!(e.contains("no such log file"), "{e}");
        assert_eq!(can_iface("vcan0"), Ok("vcan0".into()));
        assert!(can_iface("out/x.log").unwrap_err().contains("--out FILE"));
        assert!(can_iface("sim").is_err());
    }

    #[test]
    fn speeds_and_priorities_are_checked_not_clamped() {
        assert_eq!("max".parse::<Speed>(), Ok(Speed::Max));
        assert_eq!("2.5".parse::<Speed>(), Ok(Speed::Factor(2.5)));
        for bad in ["0", "-1", "nan", "inf", "1001", "fast"] {
            assert!(bad.parse::<Speed>().is_err(), "{bad}");
        }
        assert_eq!(rt_priority("50"), Ok(50));
        for bad in ["0", "100", "-5", "x"] {
            assert!(rt_priority(bad).is_err(), "{bad}");
        }
        assert_eq!(nice_value("-10"), Ok(-10));
        for bad in ["-21", "20", "x", "1.5"] {
            assert!(nice_value(bad).is_err(), "{bad}");
        }
    }
}
