//! `ddct sim`: plant and TCU cores in lockstep (issue 6).

use anyhow::Context;
use clap::Args;
use ddct::sim::{self, SimOptions, SimScenario};
use ddct::tcu::TcuConfig;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct SimArgs {
    /// Scenario file (config/scenarios/*.toml).
    #[arg(long)]
    scenario: PathBuf,
    /// TCU calibration.
    #[arg(long, default_value = "config/tcu.toml")]
    config: PathBuf,
    /// Print every row as CSV.
    #[arg(long)]
    csv: bool,
    /// Print the metrics as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: SimArgs) -> anyhow::Result<ExitCode> {
    let sc = SimScenario::load(&args.scenario)?;
    let cfg = TcuConfig::load(&args.config).context("loading the TCU calibration")?;
    let run = sim::run_scenario(&sc, &cfg, &SimOptions::default());
    if args.csv {
        println!("t,state,phase,pedal,ne,ne_ref,nc1,nc_ref,nc2,nout,x1,x1ref,x2,x2ref,tref1,tact1,tref2,tact2,engreq,te,acc,v,th_est1,th_true1,gear_o,gear_e,fault");
        for r in &run.rows {
            println!(
                "{:.3},{:?},{},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{:.3},{:.3},{:.3},{:.3},{:.1},{:.1},{:.1},{:.1},{},{:.1},{:.3},{:.2},{:.1},{:.1},{},{},{:?}",
                r.t_s, r.state, r.phase, r.pedal_pct, r.n_e_rpm, r.n_e_ref_rpm, r.n_c_rpm[0], r.n_c_ref_rpm,
                r.n_c_rpm[1], r.n_out_rpm, r.x_mm[0], r.x_ref_mm[0], r.x_mm[1], r.x_ref_mm[1],
                r.t_ref_nm[0], r.t_act_nm[0], r.t_ref_nm[1], r.t_act_nm[1],
                r.eng_req_nm.map_or("-".to_string(), |v| format!("{v:.1}")), r.t_e_nm, r.accel_mps2, r.v_kmh,
                r.theta_est_c[0], r.theta_true_c[0], r.gear_act[0], r.gear_act[1], r.fault
            );
        }
    }
    if args.json {
        let m = sim::metrics::compute(&run.rows, &cfg);
        println!("{}", serde_json::to_string_pretty(&m)?);
    }
    Ok(ExitCode::SUCCESS)
}
