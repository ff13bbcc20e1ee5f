//! Writing a diagnosis: `report.md` (for people), `report.json` (for tools: `verdict.subsystem`,
//! `verdict.effect`, `verdict.ranking`, `verdict.ambiguous_with`,
//! `verdict.outside_library_depends_on`, `how_far.output`, `how_far.rmse_before`,
//! `how_far.rmse_after`, `how_far.reduction_pct`, and the rest), SVG plots (torque-residual maps
//! before and after, traces of the main output) and the calibration (recalibrated parameter file
//! and the effect in the library's `[effects.<id>]` form, plus a TCU calibration pointing at both
//! when a template is given). Pure: returns the texts; the CLI writes them.

use crate::gap::fit::lsq;
use crate::gap::method::diagnose::{Diagnosis, Verdict};
use crate::gap::method::finding::{ClassFinding, Finding};
use crate::gap::method::where_::BiasMap;
use crate::plot::{Figure, Panel, Series, Style};
use std::fmt::Write as _;

fn f(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{v:.d$}")
    } else {
        "–".into()
    }
}

fn g(v: f64) -> String {
    if !v.is_finite() {
        "–".into()
    } else if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// The JSON report.
pub fn json(d: &Diagnosis) -> String {
    serde_json::to_string_pretty(d).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}

/// A class finding's note: how much of its interval is the form's error (docs/gap.md
/// "Magnitudes"), then its range warning.
fn class_note(c: &ClassFinding) -> String {
    let mut v = Vec::new();
    if c.model_form_rel > 0.0 {
        v.push(format!(
            "noise alone {}…{}; form ±{} %",
            g(c.noise_ci95.0),
            g(c.noise_ci95.1),
            f(100.0 * lsq::Z95 * c.model_form_rel, 1)
        ));
    }
    v.extend(c.range_warning.clone());
    v.join("; ")
}

/// One row of the findings table (without the index).
fn finding_row(fd: &Finding) -> String {
    match fd {
        Finding::Class(c) | Finding::Sensor(c) => format!(
            "{}`{}`{} | {} | {} | {} % | {} {} ({}…{}) | {}",
            if matches!(fd, Finding::Sensor(_)) { "sensor " } else { "" },
            c.class,
            if c.ambiguous_with.is_empty() {
                String::new()
            } else {
                format!(
                    " — ambiguous with {}",
                    c.ambiguous_with
                        .iter()
                        .map(|a| format!("`{a}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            },
            c.subsystem,
            c.variable,
            f(c.share_pct, 1),
            g(c.magnitude),
            c.unit,
            g(c.magnitude_ci95.0),
            g(c.magnitude_ci95.1),
            class_note(c)
        ),
        Finding::Recalibration(r) => format!(
            "recalibration `{}` | {} | — | — | {} → {} ({:+.0} %) | outside the plausible range {}…{}",
            r.key,
            fd.subsystem().map_or("—".to_string(), |s| s.to_string()),
            g(r.nominal),
            g(r.value),
            r.move_pct,
            g(r.plausible.0),
            g(r.plausible.1)
        ),
        Finding::OutsideLibrary(o) => format!(
            "outside the library | {} | {} | — | excess {} % over the noise floor | {}",
            o.subsystem,
            if o.depends_on.is_empty() {
                "—".to_string()
            } else {
                o.depends_on.join(", ")
            },
            f(100.0 * o.excess, 0),
            o.time_structure
        ),
        Finding::Nothing => "nothing | — | — | — | — | residual at the noise floor, recalibration plausible".to_string(),
    }
}

/// The Markdown report.
pub fn markdown(d: &Diagnosis) -> String {
    let mut s = String::new();
    verdict_section(&mut s, d);
    checkable_section(&mut s, d);
    data_quality_section(&mut s, d);
    where_section(&mut s, d);
    which_section(&mut s, d);
    how_far_section(&mut s, d);
    recalibration_section(&mut s, d);
    s
}

/// The title, the records and the verdict: findings, fitted shapes, the first finding and how far it closes the gap.
fn verdict_section(s: &mut String, d: &Diagnosis) {
    let v = &d.verdict;
    let _ = writeln!(s, "# Sim-to-real gap diagnosis\n");
    let _ = writeln!(s, "Training: {}  ", d.train_files.join(", "));
    let _ = writeln!(
        s,
        "Validation (held out): {}\n",
        d.validate_files.join(", ")
    );
    let _ = writeln!(s, "## Verdict\n");
    let _ = writeln!(s, "| # | finding | subsystem | variable | share of the gap closed | magnitude (95 % CI) | note |\n|---|---|---|---|---|---|---|");
    for (i, fd) in v.findings.iter().enumerate() {
        let _ = writeln!(s, "| {} | {} |", i + 1, finding_row(fd));
    }
    let _ = writeln!(
        s,
        "\nUnexplained: {} % of the recalibrated validation gap above the practical tolerance.\n",
        f(v.unexplained_pct, 1)
    );
    fitted_shapes(s, v);
    not_checkable_list(s, v);
    first_finding_summary(s, d);
}

/// The fitted shape of every class finding with one, over its variable.
fn fitted_shapes(s: &mut String, v: &Verdict) {
    for fd in &v.findings {
        if let Some(c) = fd.class() {
            if !c.shape.is_empty() {
                let pts: Vec<String> = c
                    .shape
                    .iter()
                    .map(|(z, y)| format!("({}, {})", g(*z), g(*y)))
                    .collect();
                let _ = writeln!(
                    s,
                    "- fitted shape of `{}` over {} (variable, term): {}",
                    c.class,
                    c.variable,
                    pts.join(" ")
                );
            }
        }
    }
}

/// The classes these records cannot check, with why (nothing when every class can be checked).
fn not_checkable_list(s: &mut String, v: &Verdict) {
    if !v.not_checkable.is_empty() {
        let _ = writeln!(s, "\nClasses these records cannot check:\n");
        for n in &v.not_checkable {
            let _ = writeln!(s, "- `{}`: {}", n.class, n.why);
        }
        let _ = writeln!(s);
    }
}

/// The first finding, its subsystems, the explanation, what it is ambiguous with, what the
/// missing physics depends on, and how far it closes the gap.
fn first_finding_summary(s: &mut String, d: &Diagnosis) {
    let v = &d.verdict;
    let _ = writeln!(s, "- **first finding: `{}`**", v.effect);
    let _ = writeln!(
        s,
        "- subsystem: `{}` (in order of evidence: {})",
        v.subsystem_name(),
        if v.subsystems.is_empty() {
            "none".into()
        } else {
            v.subsystems
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        }
    );
    let _ = writeln!(s, "- {}", v.explanation);
    if !v.ambiguous_with.is_empty() {
        let _ = writeln!(
            s,
            "- ambiguous with: {} (not significantly worse on the validation records)",
            v.ambiguous_list()
        );
    }
    if !v.outside_library_depends_on.is_empty() {
        let _ = writeln!(
            s,
            "- the missing physics depends on: {}",
            v.outside_library_depends_on.join(", ")
        );
    }
    let h = &d.how_far;
    let _ = writeln!(
        s,
        "- how far: `{}` RMSE {} → {} on the validation records ({}% reduction, 95 % CI {}…{} %; gap above the sensor noise {} % smaller)\n",
        h.output,
        g(h.rmse_before),
        g(h.rmse_after),
        f(h.reduction_pct, 1),
        f(h.reduction_ci95.0, 1),
        f(h.reduction_ci95.1, 1),
        f(h.gap_reduction_pct, 1)
    );
}

/// What the records can check, subsystem by subsystem, and the separability notes.
fn checkable_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "## What the records can check\n");
    let _ = writeln!(s, "| subsystem | checkable | outputs |\n|---|---|---|");
    for c in &d.checkable {
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            c.subsystem,
            if c.checkable { "yes" } else { "no" },
            c.detail
        );
    }
    let _ = writeln!(s);
    for line in &d.separability {
        let _ = writeln!(s, "- {line}");
    }
}

/// Where: residuals per subsystem, the torque bias maps and the flagged time segments.
fn where_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "\n## Where\n");
    let _ = writeln!(s, "Residuals of the recalibrated model on the validation records, standardized by each record's sensor-noise floor (0 % = noise):\n");
    let _ = writeln!(s, "| subsystem | excess over noise | z | significant | outputs (RMSE / noise) |\n|---|---|---|---|---|");
    for r in &d.where_.residual_subsystems {
        let outs: Vec<String> = r
            .outputs
            .iter()
            .map(|(n, a, b)| format!("{n} {} / {}", g(*a), g(*b)))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} % | {} | {} | {} |",
            r.subsystem,
            f(r.excess_pct, 1),
            f(r.z, 1),
            if r.significant { "yes" } else { "no" },
            outs.join("; ")
        );
    }
    for m in &d.where_.bias_maps {
        let _ = writeln!(s, "\nTorque residual bias map ({} model): {} of {} bins flagged (Benjamini–Hochberg, FDR 5 %).", m.model, m.flagged, m.tested);
        let mut cells: Vec<_> = m.cells.iter().filter(|c| c.flagged).collect();
        cells.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
        if !cells.is_empty() {
            let _ = writeln!(s, "\n| θ_c (°C) | slip (rad/s) | x_to (mm) | n | mean residual (N·m) | z |\n|---|---|---|---|---|---|");
            for c in cells.iter().take(12) {
                let _ = writeln!(
                    s,
                    "| {}…{} | {}…{} | {}…{} | {} | {} | {} |",
                    f(c.theta_c.0, 0),
                    f(c.theta_c.1, 0),
                    f(c.slip_radps.0, 0),
                    f(c.slip_radps.1, 0),
                    f(c.x_to_mm.0, 1),
                    f(c.x_to_mm.1, 1),
                    c.n,
                    f(c.mean, 2),
                    f(c.z, 1)
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "\nFlagged time segments (recalibrated model, {} tested, BH FDR 5 %):\n",
        d.where_.segments_tested
    );
    if d.where_.flagged_segments.is_empty() {
        let _ = writeln!(s, "none");
    } else {
        let _ = writeln!(s, "| file | from (s) | to (s) | mean sq. std. residual | main output |\n|---|---|---|---|---|");
        for seg in d.where_.flagged_segments.iter().take(15) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} |",
                seg.file,
                f(seg.t_start_s, 1),
                f(seg.t_end_s, 1),
                f(seg.ms_std, 2),
                seg.output
            );
        }
    }
}

/// Which: every class fitted, ranked, and the black-box discrepancy.
fn which_section(s: &mut String, d: &Diagnosis) {
    let v = &d.verdict;
    let _ = writeln!(s, "\n## Which\n");
    let _ = writeln!(s, "Every effect class fitted (a bounded piecewise-linear term in its variable, or its library member's parameters) jointly with the recalibration of its subsystem on the training records; first selection round, ranked by validation gain. Kept: ΔBIC < −10 on training, a significant validation gain (paired block bootstrap), closing ≥ 10 % of the validation gap left on its channels and at least half their practical tolerance. Ambiguous: another kept-quality class with ≥ 80 % of the best gain whose paired difference is not significant.\n");
    let _ = writeln!(s, "| rank | class | subsystem | parameters | validation score | ΔBIC | gap explained | kept-quality |\n|---|---|---|---|---|---|---|---|");
    for (i, r) in v.ranking.iter().enumerate() {
        let ps: Vec<String> = r
            .parameters
            .iter()
            .map(|(k, x)| format!("{k} = {}", g(*x)))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} % ({}…{}) | {} |",
            i + 1,
            r.effect,
            r.subsystem,
            ps.join(", "),
            f(r.validation_score, 4),
            f(r.delta_bic, 1),
            f(r.gap_explained_pct, 1),
            f(r.gap_explained_ci95.0, 1),
            f(r.gap_explained_ci95.1, 1),
            if r.credited {
                "yes".to_string()
            } else {
                format!("no: {}", r.note)
            }
        );
    }
    if let Some(bb) = &d.blackbox {
        let imp: Vec<String> = bb
            .importance
            .iter()
            .map(|(n, x)| format!("{n} {} %", f(100.0 * x, 0)))
            .collect();
        let _ = writeln!(s, "\nBlack-box discrepancy of the torque characteristic (basis over {}): validation standardized SSE {} → {}; share of its gain lost without each variable: {}.", crate::gap::method::blackbox::VARIABLES.join(", "), f(bb.sse_before, 0), f(bb.sse_after, 0), imp.join(", "));
    }
}

/// How far: equation and replay errors on the validation records.
fn how_far_section(s: &mut String, d: &Diagnosis) {
    let h = &d.how_far;
    let _ = writeln!(s, "\n## How far\n");
    let _ = writeln!(s, "Equation error on the validation records (torque at measured x_to, slip and estimated disk temperature; temperatures replayed from measured friction power; positions replayed from the requests; engine report against the flywheel balance):\n");
    let _ = writeln!(s, "| output | n | noise | RMSE nominal | recalibrated | after | fit % nominal → after | reduction (95 % CI) | gap above noise reduced |\n|---|---|---|---|---|---|---|---|---|");
    for o in &h.equation_error {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} → {} | {} % ({}…{}) | {} % |",
            o.output,
            o.n,
            g(o.noise),
            g(o.rmse_nominal),
            g(o.rmse_recalibrated),
            g(o.rmse_after),
            f(o.fit_pct_nominal, 1),
            f(o.fit_pct_after, 1),
            f(o.reduction_pct, 1),
            f(o.reduction_ci95.0, 1),
            f(o.reduction_ci95.1, 1),
            f(o.gap_reduction_pct, 1)
        );
    }
    let _ = writeln!(s, "\nReplay error (torque and temperatures simulated from the measured inputs only, the model heating itself):\n");
    let _ = writeln!(s, "| output | RMSE nominal | RMSE after |\n|---|---|---|");
    for r in &h.replay_error {
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            r.output,
            g(r.rmse_nominal),
            g(r.rmse_after)
        );
    }
}

/// What the loggers did to the channels ([`crate::gap::quality`]).
fn data_quality_section(s: &mut String, d: &Diagnosis) {
    use crate::gap::quality::DataKind;
    if d.data_quality.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\n## Data quality\n\n| record | channel | found | fix on the logger |\n|---|---|---|---|"
    );
    for f in &d.data_quality {
        let found = match &f.kind {
            DataKind::Constant { value } => format!("constant {}", g(*value)),
            DataKind::Held { every, rate_hz } => {
                format!(
                    "held: a new value every {every} samples ({} Hz)",
                    g(*rate_hz)
                )
            }
            DataKind::Spikes {
                count,
                share,
                largest,
            } => format!(
                "{count} spikes ({:.3} % of the samples), the largest {}",
                100.0 * share,
                g(*largest)
            ),
            DataKind::Quantised { step, repeated } => format!(
                "quantised to {}: {:.0} % of the readings repeat the last",
                g(*step),
                100.0 * repeated
            ),
            DataKind::Drift { wander, r2 } => format!(
                "drifts by {} over the record; the physics explains {:.0} % of its steps",
                g(*wander),
                100.0 * r2
            ),
            DataKind::Dropouts {
                runs,
                samples,
                longest_s,
            } => format!(
                "{runs} dropouts to zero ({samples} samples), the longest {} s; bridged, not compared",
                g(*longest_s)
            ),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {found} | {} |",
            f.file,
            f.channel.name(),
            f.fix
        );
    }
}

/// The recalibrated parameters and the notes.
fn recalibration_section(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(s, "\n## Recalibration\n");
    let _ = writeln!(s, "| parameter | nominal | recalibrated |\n|---|---|---|");
    for (k, a, b) in &d.recalibration {
        let _ = writeln!(s, "| {k} | {} | {} |", g(*a), g(*b));
    }
    if !d.undetermined.is_empty() {
        let _ = writeln!(
            s,
            "\nNot determined by the training records (kept nominal: moving one by {:.0} % of \
             nominal changes χ² by less than {}):\n\n\
             | parameter | fitted | Δχ² | determined by |\n|---|---|---|---|",
            100.0 * crate::gap::method::select::PLAUSIBLE_REL,
            crate::gap::method::identifiable::MIN_DELTA_CHI2
        );
        for u in &d.undetermined {
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} | {} |",
                u.key,
                g(u.fitted),
                u.delta_chi2,
                u.determined_by
            );
        }
    }
    if !d.notes.is_empty() {
        let _ = writeln!(s, "\n## Notes\n");
        for n in &d.notes {
            let _ = writeln!(s, "- {n}");
        }
    }
}

fn map_figure(m: &BiasMap) -> Figure {
    use crate::gap::method::where_::{SLIP_EDGES, THETA_EDGES};
    let mut p = Panel::new(
        format!("Torque residual, {} model", m.model),
        "θ_c (°C)",
        "mean residual (N·m)",
    );
    for b in 0..SLIP_EDGES.len() - 1 {
        let mut pts = Vec::new();
        let mut flagged = Vec::new();
        for a in 0..THETA_EDGES.len() - 1 {
            let cells: Vec<_> = m
                .cells
                .iter()
                .filter(|c| c.theta_c.0 == THETA_EDGES[a] && c.slip_radps.0 == SLIP_EDGES[b])
                .collect();
            let n: usize = cells.iter().map(|c| c.n).sum();
            if n == 0 {
                continue;
            }
            let mean = cells.iter().map(|c| c.mean * c.n as f64).sum::<f64>() / n as f64;
            let lo = THETA_EDGES[a].max(0.0);
            let hi = if THETA_EDGES[a + 1].is_finite() {
                THETA_EDGES[a + 1]
            } else {
                lo + 50.0
            };
            let x = 0.5 * (lo + hi);
            pts.push((x, mean));
            if cells.iter().any(|c| c.flagged) {
                flagged.push((x, mean));
            }
        }
        if !pts.is_empty() {
            let hi = if SLIP_EDGES[b + 1].is_finite() {
                format!("{}", SLIP_EDGES[b + 1])
            } else {
                "∞".into()
            };
            p.add(Series::line(
                format!("slip {}…{} rad/s", SLIP_EDGES[b], hi),
                pts,
            ));
        }
        if !flagged.is_empty() {
            p.add(
                Series::line("flagged (BH 5 %)", flagged)
                    .style(Style::Markers)
                    .color("#D55E00"),
            );
        }
    }
    p.legend_title = "bins".into();
    Figure::new(format!("Bias map ({})", m.model), 1).panel(p)
}

/// SVG plots: (file name, SVG).
pub fn plots(d: &Diagnosis) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for m in &d.where_.bias_maps {
        let name = if m.model == "after" {
            "residual_map_after.svg"
        } else {
            "residual_map_before.svg"
        };
        out.push((name.to_string(), map_figure(m).to_svg()));
    }
    for (i, t) in d.traces.iter().enumerate() {
        let step = (t.t.len() / 4000).max(1);
        let pick = |v: &[f64]| -> Vec<(f64, f64)> {
            t.t.iter()
                .zip(v)
                .step_by(step)
                .filter(|(_, y)| y.is_finite())
                .map(|(a, b)| (*a, *b))
                .collect()
        };
        let mut p = Panel::new(
            format!("{} — {}", t.output, t.file),
            "time (s)",
            t.output.clone(),
        );
        p.add(
            Series::line("measured", pick(&t.measured))
                .color("#000000")
                .style(Style::Markers),
        );
        p.add(Series::line("nominal model", pick(&t.nominal)).color("#D55E00"));
        p.add(
            Series::line("with the diagnosed effect", pick(&t.after))
                .color("#0072B2")
                .style(Style::Dashed),
        );
        let mut r = Panel::new("Residual", "time (s)", format!("residual of {}", t.output));
        let res = |a: &[f64]| -> Vec<(f64, f64)> {
            t.t.iter()
                .zip(t.measured.iter().zip(a))
                .step_by(step)
                .filter(|(_, (m, y))| m.is_finite() && y.is_finite())
                .map(|(x, (m, y))| (*x, m - y))
                .collect()
        };
        r.add(Series::line("nominal", res(&t.nominal)).color("#D55E00"));
        r.add(Series::line("after", res(&t.after)).color("#0072B2"));
        let fig = Figure::new("Validation trace", 1).panel(p).panel(r);
        out.push((format!("trace_{i}.svg"), fig.to_svg()));
    }
    out
}

/// The calibration: `(params.toml text, effects.toml text)` — the recalibrated parameter file
/// and the diagnosed effect in the effect library's `[effects.<id>]` form (empty when none).
pub fn calibration(d: &Diagnosis) -> Option<(String, String)> {
    let (p, set) = d.calibrated.as_ref()?;
    let mut params = String::from("# Recalibrated by `ddct gap diagnose` (see report.md).\n");
    params.push_str(&p.to_toml_string());
    let mut effects = format!(
        "# Effect diagnosed by `ddct gap diagnose`: {} (model::effects form; `ddct plant --effects`\n# and the TCU calibration's `effects = \"...\"` read it).\n",
        d.verdict.effect
    );
    effects.push_str(&set.to_toml_string());
    Some((params, effects))
}

/// A TCU calibration from a template (e.g. `config/tcu.toml`) whose `params` and `effects` keys
/// point at the files written beside it.
pub fn tcu_calibration(template: &str, params_file: &str, effects_file: &str) -> String {
    let mut out = String::new();
    let mut saw_params = false;
    let mut saw_effects = false;
    let mut in_table = false;
    for line in template.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            if !saw_effects && !in_table {
                let _ = writeln!(out, "effects = \"{effects_file}\"");
                saw_effects = true;
            }
            in_table = true;
        }
        if !in_table && (t.starts_with("params ") || t.starts_with("params=")) {
            let _ = writeln!(out, "params = \"{params_file}\"");
            saw_params = true;
            continue;
        }
        if !in_table
            && (t.starts_with("effects ")
                || t.starts_with("effects=")
                || t.starts_with("# effects ="))
        {
            if !saw_effects {
                let _ = writeln!(out, "effects = \"{effects_file}\"");
                saw_effects = true;
            }
            continue;
        }
        let _ = writeln!(out, "{line}");
    }
    if !saw_params {
        out = format!("params = \"{params_file}\"\n{out}");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tcu_template_points_at_the_calibration() {
        let t = "# c\nparams = \"params.toml\"\n# effects = \"x.toml\"\n\n[compensation]\ntemperature = true\n";
        let out = tcu_calibration(t, "params.toml", "effects.toml");
        assert!(out.contains("params = \"params.toml\"\n"));
        assert_eq!(out.matches("effects = \"effects.toml\"").count(), 1);
        let i = out.find("effects =").unwrap();
        let j = out.find("[compensation]").unwrap();
        assert!(i < j, "top-level key before the first table");
    }
}
