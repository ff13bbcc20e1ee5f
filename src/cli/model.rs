//! `ddct model`: evaluate the clutch torque characteristic (13), its inverse, and write the
//! paper-style SVG figures (issue 4).

use anyhow::Context;
use clap::Subcommand;
use ddct::model::{clutch, Params};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum ModelCmd {
    /// Torque of the clutch characteristic (13) at a bearing position, slip and temperature.
    Torque {
        /// Throwout-bearing position (mm).
        #[arg(long = "x-to", allow_negative_numbers = true)]
        x_to: f64,
        /// Slip speed ω_f − ω_c (rad/s); the torque has its sign.
        #[arg(long, allow_negative_numbers = true)]
        slip: f64,
        /// Clutch temperature (°C).
        #[arg(long, allow_negative_numbers = true)]
        temp: f64,
        /// Print `{"torque_nm": ...}`.
        #[arg(long)]
        json: bool,
        /// Parameter file (default: the built-in config/params.toml).
        #[arg(long, env = "DDCT_PARAMS")]
        params: Option<PathBuf>,
    },
    /// Bearing position that gives a torque (magnitude) at a slip and temperature: inverse of (13).
    Invert {
        /// Requested torque (N·m).
        #[arg(long, allow_negative_numbers = true)]
        torque: f64,
        /// Slip speed (rad/s).
        #[arg(long, allow_negative_numbers = true)]
        slip: f64,
        /// Clutch temperature (°C).
        #[arg(long, allow_negative_numbers = true)]
        temp: f64,
        /// Print `{"x_to_mm": ..., "saturated": bool}`.
        #[arg(long)]
        json: bool,
        /// Parameter file (default: the built-in config/params.toml).
        #[arg(long, env = "DDCT_PARAMS")]
        params: Option<PathBuf>,
    },
    /// Write the SVG figures of the paper's Fig. 4, 5a–c and 7a–b.
    Plot {
        /// Output directory (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Parameter file (default: the built-in config/params.toml).
        #[arg(long, env = "DDCT_PARAMS")]
        params: Option<PathBuf>,
    },
}

fn load(path: &Option<PathBuf>) -> anyhow::Result<Params> {
    match path {
        Some(p) => Params::load(p).with_context(|| format!("loading {}", p.display())),
        None => Ok(Params::default()),
    }
}

fn finite(name: &str, v: f64) -> anyhow::Result<()> {
    anyhow::ensure!(v.is_finite(), "--{name} must be a finite number, got {v}");
    Ok(())
}

pub fn run(cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        ModelCmd::Torque {
            x_to,
            slip,
            temp,
            json,
            params,
        } => {
            finite("x-to", x_to)?;
            finite("slip", slip)?;
            finite("temp", temp)?;
            let p = load(&params)?;
            let t = clutch::torque(&p.clutch, x_to, slip, temp);
            if json {
                println!("{}", serde_json::json!({ "torque_nm": t }));
            } else {
                println!("{t:.6} N·m");
            }
        }
        ModelCmd::Invert {
            torque,
            slip,
            temp,
            json,
            params,
        } => {
            let p = load(&params)?;
            let inv = clutch::invert(&p.clutch, torque, slip, temp)?;
            if json {
                println!("{}", serde_json::to_string(&inv)?);
            } else {
                println!(
                    "{:.6} mm{}",
                    inv.x_to_mm,
                    if inv.saturated { " (saturated)" } else { "" }
                );
            }
        }
        ModelCmd::Plot { out, params } => {
            let p = load(&params)?;
            std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
            let files = ddct::plot::paper::write_all(&p, &out)
                .with_context(|| format!("writing figures to {}", out.display()))?;
            for f in files {
                println!("{}", f.display());
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
