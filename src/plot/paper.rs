//! The paper's characteristic figures, computed from the parameters and rendered as SVG with
//! [`crate::plot`] (above the model, which never renders): Fig. 4 (equivalent friction radius (6) over slip and temperature), Fig. 5a–c
//! (flat-spring compression (7) over x_to at several temperatures, spring load (10) over u,
//! load over x_to) and Fig. 7a–b (torque (13) over x_to for several slips at several temperatures,
//! and for several temperatures at several slips). Pure: [`figures`] returns (file name, SVG);
//! [`write_all`] is the only function that touches the file system.

use super::{ramp, Figure, LegendPos, Panel, Series};
use crate::model::clutch;
use crate::model::params::{ClutchParams, Params};
use std::path::{Path, PathBuf};

const TEMPS: [f64; 6] = [25.0, 70.0, 110.0, 150.0, 200.0, 240.0];

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .collect()
}

/// The points `(x, f(x))` at `n` evenly spaced `x` from `a` to `b`.
fn curve(a: f64, b: f64, n: usize, f: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
    linspace(a, b, n).into_iter().map(|x| (x, f(x))).collect()
}

/// All figures as (file name, SVG text).
pub fn figures(p: &Params) -> Vec<(&'static str, String)> {
    let c = &p.clutch;
    vec![
        ("fig4_r_mu.svg", fig4_r_mu(c)),
        ("fig5a_u_fs.svg", fig5a_u_fs(c)),
        ("fig5b_spring_load.svg", fig5b_spring_load(c)),
        ("fig5c_force_x_to.svg", fig5c_force_x_to(c)),
        ("fig7a_torque_x_slip.svg", fig7a_torque_x_slip(c)),
        ("fig7b_torque_x_temp.svg", fig7b_torque_x_temp(c)),
    ]
}

/// Fig. 4: R_μ over slip (two ranges, one curve per temperature) and over temperature (one
/// curve per slip).
fn fig4_r_mu(c: &ClutchParams) -> String {
    let cols = ramp(TEMPS.len());
    let mut a = Panel::new("(a) R_μ over slip", "slip ω_fc (rad/s)", "R_μ (mm)")
        .legend_title("θ_fp")
        .legend_pos(LegendPos::BottomRight);
    let mut b = Panel::new("(b) low slip detail", "slip ω_fc (rad/s)", "R_μ (mm)")
        .legend_title("θ_fp")
        .legend_pos(LegendPos::BottomRight);
    for (k, &th) in TEMPS.iter().enumerate() {
        let pts = curve(0.0, 100.0, 201, |w| 1e3 * clutch::r_mu(c, w, th));
        a.add(Series::line(format!("{th:.0} °C"), pts).color(cols[k].clone()));
        let pts = curve(0.0, 2.0, 201, |w| 1e3 * clutch::r_mu(c, w, th));
        b.add(Series::line(format!("{th:.0} °C"), pts).color(cols[k].clone()));
    }
    let slips = [0.0, 0.1, 1.0, 10.0, 100.0];
    let sc = ramp(slips.len());
    let mut cpanel = Panel::new("(c) R_μ over temperature", "θ_fp (°C)", "R_μ (mm)")
        .legend_title("ω_fc")
        .legend_pos(LegendPos::BottomLeft);
    for (k, &w) in slips.iter().enumerate() {
        let pts = curve(0.0, 300.0, 151, |th| 1e3 * clutch::r_mu(c, w, th));
        cpanel.add(Series::line(format!("{w} rad/s"), pts).color(sc[k].clone()));
    }
    Figure::new("Fig. 4 — equivalent friction radius (6)", 3)
        .panel(a)
        .panel(b)
        .panel(cpanel)
        .to_svg()
}

/// Fig. 5a: the flat spring's compression u_fs over x_to, one curve per temperature.
fn fig5a_u_fs(c: &ClutchParams) -> String {
    let cols = ramp(TEMPS.len());
    let mut a = Panel::new(
        "Fig. 5a — flat-spring compression (7)",
        "x_to (mm)",
        "u_fs (mm)",
    )
    .legend_title("θ_fs")
    .x_range(0.0, 8.0);
    for (k, &th) in TEMPS.iter().enumerate() {
        let pts = curve(0.0, 8.0, 401, |x| clutch::u_fs(c, x, th));
        a.add(Series::line(format!("{th:.0} °C"), pts).color(cols[k].clone()));
    }
    Figure::new("", 1).panel(a).to_svg()
}

/// Fig. 5b: the flat spring's load F over its compression u.
fn fig5b_spring_load(c: &ClutchParams) -> String {
    let umax = clutch::u_fs_max(c, 300.0);
    let mut b = Panel::new("Fig. 5b — flat-spring load (10)", "u_fs (mm)", "F_fc (kN)");
    b.legend = false;
    b.add(Series::line(
        "F(u)",
        curve(0.0, umax, 201, |u| 1e-3 * clutch::spring_force(c, u)),
    ));
    Figure::new("", 1).panel(b).to_svg()
}

/// Fig. 5c: the load F over x_to, one curve per temperature.
fn fig5c_force_x_to(c: &ClutchParams) -> String {
    let cols = ramp(TEMPS.len());
    let mut cc = Panel::new(
        "Fig. 5c — load over bearing position (7)–(10)",
        "x_to (mm)",
        "F_fc (kN)",
    )
    .legend_title("θ_fs")
    .x_range(0.0, 8.0);
    for (k, &th) in TEMPS.iter().enumerate() {
        let pts = curve(0.0, 8.0, 401, |x| 1e-3 * clutch::normal_force(c, x, th));
        cc.add(Series::line(format!("{th:.0} °C"), pts).color(cols[k].clone()));
    }
    Figure::new("", 1).panel(cc).to_svg()
}

/// Fig. 7a: torque over x_to for several slips, one panel per temperature.
fn fig7a_torque_x_slip(c: &ClutchParams) -> String {
    let slips7 = [0.1, 1.0, 10.0, 50.0, 200.0];
    let sc = ramp(slips7.len());
    let mut fig = Figure::new(
        "Fig. 7a — torque (13) over x_to and slip, by temperature",
        3,
    );
    for &th in &[25.0, 140.0, 240.0] {
        let mut pnl = torque_panel(format!("θ_c = {th:.0} °C"), "ω_fc");
        for (k, &w) in slips7.iter().enumerate() {
            let pts = curve(2.5, 7.5, 401, |x| clutch::torque(c, x, w, th));
            pnl.add(Series::line(format!("{w} rad/s"), pts).color(sc[k].clone()));
        }
        fig = fig.panel(pnl);
    }
    fig.to_svg()
}

/// Fig. 7b: torque over x_to for several temperatures, one panel per slip.
fn fig7b_torque_x_temp(c: &ClutchParams) -> String {
    let cols = ramp(TEMPS.len());
    let mut fig = Figure::new(
        "Fig. 7b — torque (13) over x_to and temperature, by slip",
        2,
    );
    for &w in &[0.5, 50.0] {
        let mut pnl = torque_panel(format!("ω_fc = {w} rad/s"), "θ_c");
        for (k, &th) in TEMPS.iter().enumerate() {
            let pts = curve(2.5, 7.5, 401, |x| clutch::torque(c, x, w, th));
            pnl.add(Series::line(format!("{th:.0} °C"), pts).color(cols[k].clone()));
        }
        fig = fig.panel(pnl);
    }
    fig.to_svg()
}

/// A panel of Fig. 7: torque over x_to (2.5–7.5 mm, 0–700 N·m), its curves told apart by
/// `legend`.
fn torque_panel(title: String, legend: &str) -> Panel {
    Panel::new(title, "x_to (mm)", "T_fc (N·m)")
        .legend_title(legend)
        .x_range(2.5, 7.5)
        .y_range(0.0, 700.0)
}

/// Writes every figure into `dir`; returns the paths written.
pub fn write_all(p: &Params, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    for (name, svg) in figures(p) {
        let path = dir.join(name);
        std::fs::write(&path, svg)?;
        paths.push(path);
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_figures_render() {
        let f = figures(&Params::default());
        assert_eq!(f.len(), 6);
        for (name, svg) in f {
            assert!(svg.starts_with("<svg"), "{name}");
            assert!(svg.contains("(mm)") || svg.contains("(rad/s)"), "{name}");
        }
    }
}
