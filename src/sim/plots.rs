//! SVG figures of a run (with `crate::plot`): engine and clutch speeds with the TCU's references,
//! clutch torque reference (TCU_Estimates) against the actual torque (BENCH_Torque), bearing
//! position request against the measured position, estimated clutch temperatures against
//! SIM_Truth, vehicle acceleration, speed and pedal, and the TCU state and the active gear as
//! labelled lanes. Fault codes are marked where they appear; a dropout of the bus (no row for
//! more than [`MAX_GAP_S`]) leaves the lines open.

use super::Row;
use crate::can::messages::{FaultCode, GearActive, TcuState};
use crate::plot::{Figure, Panel, Series, Style, PALETTE};

/// Rows further apart than this (five 10 ms cycles) are a dropout, not drawn across.
pub const MAX_GAP_S: f64 = 0.05;

fn series(rows: &[Row], name: &str, f: impl Fn(&Row) -> f64) -> Series {
    Series::line(name, rows.iter().map(|r| (r.t_s, f(r))).collect()).max_gap(MAX_GAP_S)
}

/// The times a fault code appears (a change to a code other than None), with its name.
pub(crate) fn fault_events(rows: &[Row]) -> Vec<(f64, String)> {
    let mut last = FaultCode::None;
    let mut out = Vec::new();
    for r in rows {
        if r.fault != last && r.fault != FaultCode::None {
            out.push((r.t_s, r.fault.label().to_string()));
        }
        last = r.fault;
    }
    out
}

/// A lane panel: one named row per value.
fn lanes(title: &str, labels: Vec<(f64, String)>) -> Panel {
    let n = labels.len() as f64;
    let mut p = Panel::new(title, "t (s)", "")
        .y_labels(labels)
        .y_range(-0.5, n - 0.5);
    p.legend = false;
    p
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
    let mut speeds = speeds_panel(rows);
    let mut state = state_panel(rows);
    for (t, name) in fault_events(rows) {
        state.marker(t, name.clone());
        speeds.marker(t, name);
    }
    Figure::new(title, 2)
        .panel(speeds)
        .panel(torque_panel(rows))
        .panel(position_panel(rows))
        .panel(temperature_panel(rows))
        .panel(acceleration_panel(rows))
        .panel(speed_pedal_panel(rows))
        .panel(state)
        .panel(gear_panel(rows))
        .to_svg()
}

/// The `i`-th colour of the palette (cycling).
fn palette(i: usize) -> &'static str {
    PALETTE[i % PALETTE.len()]
}

/// Engine and clutch speeds, with the TCU's references when the bus carries them.
fn speeds_panel(rows: &[Row]) -> Panel {
    let mut speeds = Panel::new("Engine and clutch speeds", "t (s)", "n (rpm)");
    speeds.add(series(rows, "engine", |r| r.n_e_rpm).color(palette(0)));
    add_nonzero(
        &mut speeds,
        series(rows, "engine ref", |r| r.n_e_ref_rpm)
            .color(palette(0))
            .style(Style::Dashed),
    );
    speeds.add(series(rows, "clutch 1 (odd)", |r| r.n_c_rpm[0]).color(palette(1)));
    speeds.add(series(rows, "clutch 2 (even)", |r| r.n_c_rpm[1]).color(palette(2)));
    add_nonzero(
        &mut speeds,
        series(rows, "active clutch ref", |r| r.n_c_ref_rpm)
            .color(palette(6))
            .style(Style::Dotted),
    );
    speeds
}

/// Each clutch's torque reference (TCU_Estimates) against its actual torque (BENCH_Torque),
/// with the engine torque.
fn torque_panel(rows: &[Row]) -> Panel {
    let mut torque = Panel::new("Clutch torque: reference vs actual", "t (s)", "T (N·m)");
    torque.add(
        series(rows, "T_ref 1", |r| r.t_ref_nm[0])
            .color(palette(1))
            .style(Style::Dashed),
    );
    torque.add(series(rows, "T_actual 1", |r| r.t_act_nm[0]).color(palette(1)));
    torque.add(
        series(rows, "T_ref 2", |r| r.t_ref_nm[1])
            .color(palette(2))
            .style(Style::Dashed),
    );
    torque.add(series(rows, "T_actual 2", |r| r.t_act_nm[1]).color(palette(2)));
    torque.add(
        series(rows, "engine", |r| r.t_e_nm)
            .color(palette(0))
            .style(Style::Dotted),
    );
    torque
}

/// Each throwout bearing's position request against its measured position.
fn position_panel(rows: &[Row]) -> Panel {
    let mut x = Panel::new("Throwout-bearing position", "t (s)", "x_to (mm)");
    x.add(
        series(rows, "x_ref 1", |r| r.x_ref_mm[0])
            .color(palette(1))
            .style(Style::Dashed),
    );
    x.add(series(rows, "x 1", |r| r.x_mm[0]).color(palette(1)));
    x.add(
        series(rows, "x_ref 2", |r| r.x_ref_mm[1])
            .color(palette(2))
            .style(Style::Dashed),
    );
    x.add(series(rows, "x 2", |r| r.x_mm[1]).color(palette(2)));
    x
}

/// The estimated clutch temperatures against SIM_Truth, with the housing's.
fn temperature_panel(rows: &[Row]) -> Panel {
    let mut temps = Panel::new(
        "Clutch temperatures: estimate (17) vs truth (16)",
        "t (s)",
        "θ (°C)",
    );
    temps.add(
        series(rows, "θ̂ clutch 1", |r| r.theta_est_c[0])
            .color(palette(1))
            .style(Style::Dashed),
    );
    temps.add(series(rows, "θ clutch 1 (SIM_Truth)", |r| r.theta_true_c[0]).color(palette(1)));
    temps.add(
        series(rows, "θ̂ clutch 2", |r| r.theta_est_c[1])
            .color(palette(2))
            .style(Style::Dashed),
    );
    temps.add(series(rows, "θ clutch 2 (SIM_Truth)", |r| r.theta_true_c[1]).color(palette(2)));
    temps.add(
        series(rows, "housing", |r| r.housing_c)
            .color(palette(6))
            .style(Style::Dotted),
    );
    temps
}

/// The vehicle's acceleration.
fn acceleration_panel(rows: &[Row]) -> Panel {
    let mut acc = Panel::new("Vehicle acceleration", "t (s)", "a (m/s²)");
    acc.add(series(rows, "a (BENCH_Vehicle)", |r| r.accel_mps2).color(palette(0)));
    acc
}

/// The vehicle's speed and the pedal.
fn speed_pedal_panel(rows: &[Row]) -> Panel {
    let mut v = Panel::new("Vehicle speed and pedal", "t (s)", "v (km/h), pedal (%)");
    v.add(series(rows, "v (km/h)", |r| r.v_kmh).color(palette(0)));
    v.add(
        series(rows, "pedal (%)", |r| r.pedal_pct)
            .color(palette(4))
            .style(Style::Dashed),
    );
    v
}

/// The TCU state as labelled lanes (fault codes are marked by the caller).
fn state_panel(rows: &[Row]) -> Panel {
    let state_index = |s: TcuState| TcuState::ALL.iter().position(|x| *x == s).unwrap_or(0) as f64;
    let mut state = lanes(
        "TCU state (fault codes marked)",
        TcuState::ALL
            .iter()
            .map(|s| (state_index(*s), s.label().to_string()))
            .collect(),
    );
    state.add(
        series(rows, "TcuState", |r| state_index(r.state))
            .steps()
            .color(palette(6)),
    );
    state
}

/// The active gear as labelled lanes.
fn gear_panel(rows: &[Row]) -> Panel {
    let gear_index =
        |g: GearActive| GearActive::ALL.iter().position(|x| *x == g).unwrap_or(0) as f64;
    let mut gear = lanes(
        "Active gear",
        GearActive::ALL
            .iter()
            .map(|g| (gear_index(*g), g.label().to_string()))
            .collect(),
    );
    gear.add(
        series(rows, "gear", |r| gear_index(r.gear_active.into()))
            .steps()
            .color(palette(3)),
    );
    gear
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
