//! SVG figures of a run (with `crate::plot`): engine and clutch speeds with the TCU's references,
//! clutch torque reference (TCU_Estimates) against the actual torque (BENCH_Torque), bearing
//! position request against the measured position, estimated clutch temperatures against
//! SIM_Truth, vehicle acceleration and speed, and the TCU state.

use super::Row;
use crate::plot::{Figure, Panel, Series, Style, PALETTE};

fn series(rows: &[Row], name: &str, f: impl Fn(&Row) -> f64) -> Series {
    Series::line(name, rows.iter().map(|r| (r.t_s, f(r))).collect())
}

/// Adds a series unless it is zero throughout (e.g. the TCU's internal references on a recorded
/// bus, which does not carry them).
fn add_nonzero(p: &mut Panel, s: Series) {
    if s.points.iter().any(|(_, y)| *y != 0.0) {
        p.add(s);
    }
}

/// The figure of one run, as an SVG document.
pub fn run_figure(title: &str, rows: &[Row]) -> String {
    let c = |i: usize| PALETTE[i % PALETTE.len()];
    let mut speeds = Panel::new("Engine and clutch speeds", "t (s)", "n (rpm)");
    speeds.add(series(rows, "engine", |r| r.n_e_rpm).color(c(0)));
    add_nonzero(
        &mut speeds,
        series(rows, "engine ref", |r| r.n_e_ref_rpm)
            .color(c(0))
            .style(Style::Dashed),
    );
    speeds.add(series(rows, "clutch 1 (odd)", |r| r.n_c_rpm[0]).color(c(1)));
    speeds.add(series(rows, "clutch 2 (even)", |r| r.n_c_rpm[1]).color(c(2)));
    add_nonzero(
        &mut speeds,
        series(rows, "active clutch ref", |r| r.n_c_ref_rpm)
            .color(c(6))
            .style(Style::Dotted),
    );

    let mut torque = Panel::new("Clutch torque: reference vs actual", "t (s)", "T (N·m)");
    torque.add(
        series(rows, "T_ref 1", |r| r.t_ref_nm[0])
            .color(c(1))
            .style(Style::Dashed),
    );
    torque.add(series(rows, "T_actual 1", |r| r.t_act_nm[0]).color(c(1)));
    torque.add(
        series(rows, "T_ref 2", |r| r.t_ref_nm[1])
            .color(c(2))
            .style(Style::Dashed),
    );
    torque.add(series(rows, "T_actual 2", |r| r.t_act_nm[1]).color(c(2)));
    torque.add(
        series(rows, "engine", |r| r.t_e_nm)
            .color(c(0))
            .style(Style::Dotted),
    );

    let mut x = Panel::new("Throwout-bearing position", "t (s)", "x_to (mm)");
    x.add(
        series(rows, "x_ref 1", |r| r.x_ref_mm[0])
            .color(c(1))
            .style(Style::Dashed),
    );
    x.add(series(rows, "x 1", |r| r.x_mm[0]).color(c(1)));
    x.add(
        series(rows, "x_ref 2", |r| r.x_ref_mm[1])
            .color(c(2))
            .style(Style::Dashed),
    );
    x.add(series(rows, "x 2", |r| r.x_mm[1]).color(c(2)));

    let mut temps = Panel::new(
        "Clutch temperatures: estimate (17) vs truth (16)",
        "t (s)",
        "θ (°C)",
    );
    temps.add(
        series(rows, "θ̂ clutch 1", |r| r.theta_est_c[0])
            .color(c(1))
            .style(Style::Dashed),
    );
    temps.add(series(rows, "θ clutch 1 (SIM_Truth)", |r| r.theta_true_c[0]).color(c(1)));
    temps.add(
        series(rows, "θ̂ clutch 2", |r| r.theta_est_c[1])
            .color(c(2))
            .style(Style::Dashed),
    );
    temps.add(series(rows, "θ clutch 2 (SIM_Truth)", |r| r.theta_true_c[1]).color(c(2)));
    temps.add(
        series(rows, "housing", |r| r.housing_c)
            .color(c(6))
            .style(Style::Dotted),
    );

    let mut acc = Panel::new("Vehicle acceleration", "t (s)", "a (m/s²)");
    acc.add(series(rows, "a (BENCH_Vehicle)", |r| r.accel_mps2).color(c(0)));

    let mut v = Panel::new(
        "Vehicle speed, pedal, gear, TCU state",
        "t (s)",
        "v (km/h), pedal (%)",
    );
    v.add(series(rows, "v (km/h)", |r| r.v_kmh).color(c(0)));
    v.add(
        series(rows, "pedal (%)", |r| r.pedal_pct)
            .color(c(4))
            .style(Style::Dashed),
    );
    v.add(series(rows, "gear ×10", |r| f64::from(r.gear_active) * 10.0).color(c(3)));
    v.add(
        series(rows, "TcuState ×10", |r| f64::from(r.state as u8) * 10.0)
            .color(c(6))
            .style(Style::Dotted),
    );

    Figure::new(title, 2)
        .panel(speeds)
        .panel(torque)
        .panel(x)
        .panel(temps)
        .panel(acc)
        .panel(v)
        .to_svg()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_every_panel() {
        let rows: Vec<Row> = (0..50)
            .map(|k| Row {
                t_s: k as f64 * 0.01,
                n_e_rpm: 800.0 + k as f64,
                ..Default::default()
            })
            .collect();
        let svg = run_figure("t", &rows);
        assert!(svg.starts_with("<svg"));
        for title in [
            "Engine and clutch speeds",
            "Clutch torque",
            "Vehicle acceleration",
        ] {
            assert!(svg.contains(title), "{title}");
        }
    }
}
